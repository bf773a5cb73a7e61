"""Engine lane: plain numpy, no Blender. The engine is ``voxgi.voxgi_addon`` (see
``tests/conftest.py``); importing it never imports bpy."""

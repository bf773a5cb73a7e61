"""GFG scene export and import on the Blender side: bpy datablocks ↔ ``voxgi_addon.files.gfg``."""

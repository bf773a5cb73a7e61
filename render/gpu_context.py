"""Whether the GPU tracer can run now, and getting a GPU context in background mode.

In Blender's UI the main thread always has a GPU context. In background mode (``blender -b``,
``import bpy``) the ``gpu`` module only works once a render engine with
``bl_use_gpu_context`` has rendered (docs/blender_facts.md "The gpu module in background
mode"); ``ensure_gpu_context`` renders one empty 4 × 4 frame of a throwaway scene with the
VoxGI engine to get there. Setting the environment variable ``VOXGI_NO_GPU`` (any non-empty
value) makes the GPU unavailable, which is how the numpy fallback is forced.
"""
from __future__ import annotations

import os

import bpy

BOOTSTRAP_SCENE = ".voxgi_gpu_context"


def gpu_usable() -> tuple[bool, str]:
    """(True, "") when compute shaders can run now, else (False, why)."""
    if os.environ.get("VOXGI_NO_GPU"):
        return False, "the VOXGI_NO_GPU environment variable is set"
    try:
        import gpu
        gpu.types.GPUTexture((1, 1), format="RGBA32F")
    except Exception as error:  # the gpu module raises SystemError/RuntimeError without context
        return False, str(error) or type(error).__name__
    return True, ""


def ensure_gpu_context() -> tuple[bool, str]:
    """``gpu_usable()``, first rendering the bootstrap frame in background mode if needed."""
    ready, why = gpu_usable()
    if ready or os.environ.get("VOXGI_NO_GPU") or not bpy.app.background:
        return ready, why
    scene = bpy.data.scenes.new(BOOTSTRAP_SCENE)
    camera_data = bpy.data.cameras.new(BOOTSTRAP_SCENE)
    camera = bpy.data.objects.new(BOOTSTRAP_SCENE, camera_data)
    try:
        scene.collection.objects.link(camera)
        scene.camera = camera
        scene.render.engine = "VOXGI"
        scene.render.resolution_x = scene.render.resolution_y = 4
        bpy.ops.render.render(scene=scene.name)
    except RuntimeError as error:
        return False, f"no GPU context could be created: {str(error).strip()}"
    finally:
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)
        bpy.data.scenes.remove(scene)
    return gpu_usable()

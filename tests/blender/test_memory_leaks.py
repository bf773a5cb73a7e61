"""Nothing the add-on allocates outlives the process: no "Not freed memory blocks" at exit.

Blender's leak detector runs as a static destructor when the process exits, after Python has
shut down, and prints ``Error: Not freed memory blocks: N, total unfreed memory … MB`` to
stdout when guarded allocations are left — in the PyPI bpy module too, without
``--debug-memory`` (docs/gi_pipeline.md, "GPU resources at exit"). So the run has to be its own
process, ending normally (``os._exit`` would skip the report): a fresh ``python`` with bpy
imports the repository as the add-on ``voxgi`` (as conftest.py does), voxelizes the demo
scene, updates GI, writes the GPU preview, renders F12 with the VoxGI engine, draws the live
viewport and prepares a debug view, all tiny.
"""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys
import textwrap

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
DONE = "VOXGI_LEAK_SCRIPT_DONE"
LEAK_REPORT = "Not freed memory blocks"

SCRIPT = textwrap.dedent(
    f"""
    import importlib, pathlib, sys
    import bpy

    repo, tmp = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    (tmp / "voxgi").symlink_to(repo, target_is_directory=True)
    sys.path.insert(0, str(tmp))
    importlib.import_module("voxgi").register()
    from voxgi.blender.demo_scene import build_demo_scene
    from voxgi.blender.session import scene_session

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build_demo_scene(scene)
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.2, 2, "32"
    session = scene_session(scene.name_full)
    assert bpy.ops.voxgi.voxelize() == {{"FINISHED"}}, session.last_report
    assert bpy.ops.voxgi.update() == {{"FINISHED"}}, session.last_report
    status = bpy.ops.voxgi.render_preview(filepath=str(tmp / "preview.exr"),
                                          resolution_x=16, resolution_y=12)
    assert status == {{"FINISHED"}}, session.last_report
    assert session.tracer_used == "GPU", session.last_report
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    scene.render.resolution_percentage = 100
    session.tracer_used = ""
    bpy.ops.render.render()
    assert session.tracer_used == "GPU", "F12 did not trace on the GPU"
    # The live viewport and a debug view keep textures between redraws too.
    import gpu
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.viewport import ViewportRenderer, draw_view
    from voxgi.ui.debug_draw import _drawers
    from voxgi.render.debug_draw import DebugDrawer
    live = live_gi(scene.name_full)
    live.update(scene, bpy.context.evaluated_depsgraph_get())
    camera = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    offscreen = gpu.types.GPUOffScreen(16, 12)
    renderer = ViewportRenderer()
    for _ in range(200):  # the first draws make the view ready (render/viewport_prepare.py)
        with offscreen.bind():
            drawn = draw_view(renderer, scene, depsgraph, camera.matrix_world.inverted(),
                              camera.calc_matrix_camera(depsgraph, x=16, y=12), 16, 12)
        if drawn and renderer.traces:
            break
    assert renderer.traces, renderer.status
    offscreen.free()
    drawer = _drawers[scene.name_full] = DebugDrawer()
    assert drawer.prepare(live.staged.state, "VOXELS", 0, 0, "ALBEDO") > 0
    print("{DONE}", flush=True)
    """
)


def test_demo_run_frees_everything_at_exit(tmp_path):
    env = dict(os.environ)
    env.pop("VOXGI_NO_GPU", None)  # the GPU objects are what could leak
    run = subprocess.run([sys.executable, "-c", SCRIPT, str(REPO_ROOT), str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=600)
    output = run.stdout + run.stderr
    assert run.returncode == 0 and DONE in run.stdout, output[-4000:]
    leak = [line for line in output.splitlines() if LEAK_REPORT in line]
    assert not leak, f"Blender reported leaked memory at exit: {leak}"

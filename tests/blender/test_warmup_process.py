"""The kernels' machine code built by another process (render/warmup_process.py;
docs/gi_pipeline.md "A first session's kernels, built by another process").

The child runs for real on a saved demo file with a Mesa shader cache of its own: it opens the
file, converges its Rendered view, renders a small F12 preview and says so; the cache it filled
then holds the kernels a new session's view dispatches (counted: entering Rendered mode in a
third process on that cache adds at most a few variants to it, where the cold session added
dozens). The timer's side is checked headless: which files start a child, once per version.
"""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import bpy
from test_viewport import gpu_ready

REGION = (320, 180)


def saved_demo(path: pathlib.Path) -> str:
    from voxgi.blender.demo_scene import build_demo_scene

    scene = bpy.context.scene
    build_demo_scene(scene)
    scene.render.engine = "VOXGI"
    scene.voxgi_viewport.samples = 2
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return str(path)


def cache_files(directory: pathlib.Path) -> set[str]:
    return {str(p.relative_to(directory)) for p in directory.rglob("*") if p.is_file()}


def shader_cache_env(directory: pathlib.Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "MESA_SHADER_CACHE_DISABLE"}
    env["MESA_SHADER_CACHE_DIR"] = str(directory)
    return env


ENTER = r"""
import sys, time, types
root, blend, width, height = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
import bpy, gpu, importlib.util
spec = importlib.util.spec_from_file_location("voxgi", root + "/__init__.py",
                                              submodule_search_locations=[root])
voxgi = importlib.util.module_from_spec(spec); sys.modules["voxgi"] = voxgi
spec.loader.exec_module(voxgi); voxgi.register()
bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
from voxgi.render.gpu_context import ensure_gpu_context
from voxgi.render.viewport import view_draw, view_update
from voxgi.render.warmup_process import _Engine, _view
from voxgi.blender import jobs
ensure_gpu_context(); jobs.synchronous = False
scene = bpy.context.scene; graph = bpy.context.evaluated_depsgraph_get()
view, window = _view(scene, graph, width, height)
context = types.SimpleNamespace(region=types.SimpleNamespace(width=width, height=height),
    region_data=types.SimpleNamespace(view_matrix=view, window_matrix=window))
engine = _Engine(); off = gpu.types.GPUOffScreen(width, height)
view_update(engine, context, graph)
for _ in range(400):
    jobs.drain()
    with off.bind():
        view_draw(engine, context, graph); off.texture_color.read()
    if engine.voxgi_viewport.traces >= 2:
        break
    time.sleep(0.005)
jobs.wait_idle(60); off.free()
print("ENTERED", engine.voxgi_viewport.traces, flush=True)
"""


def enter_in_new_process(blend: str, cache: pathlib.Path) -> str:
    """Rendered mode entered in a fresh process on ``cache``, to its second slice."""
    from voxgi.render.warmup_process import ROOT

    done = subprocess.run([sys.executable, "-c", ENTER, str(ROOT), blend, *map(str, REGION)],
                          env=shader_cache_env(cache), capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return done.stdout


def test_the_child_fills_the_shader_cache_a_new_session_reads(tmp_path):
    """The child converges the file's view and renders F12's kernels; a new session entering
    Rendered mode on its cache builds at most a few variants more, where a session on an
    empty cache builds every kernel it dispatches."""
    gpu_ready()  # the child and the sessions make their own; this one must have one too
    from voxgi.render import warmup_process

    blend = saved_demo(tmp_path / "demo.blend")
    cold = tmp_path / "cold_cache"
    assert "ENTERED" in enter_in_new_process(blend, cold)
    built_cold = cache_files(cold)
    warm = tmp_path / "warm_cache"
    child = warmup_process.launch(blend, *REGION, wait=True, env=shader_cache_env(warm))
    assert child.returncode == 0, child.output[-3000:]
    assert warmup_process.DONE in child.output
    compiled = int(child.output.split(warmup_process.DONE)[1].split("draws, ")[1].split()[0])
    assert compiled >= 10, child.output[-500:]  # the view's and F12's kernels
    filled = cache_files(warm)
    assert len(filled) >= len(built_cold), (len(filled), len(built_cold))
    assert "ENTERED" in enter_in_new_process(blend, warm)
    added = cache_files(warm) - filled
    # the new session's kernels came from the child's cache: a cold session built them all
    assert len(added) <= max(3, len(built_cold) // 10), (len(added), len(built_cold))


def test_which_files_start_a_child(tmp_path, monkeypatch):
    """A saved VoxGI file starts one child per version (its stamp); an unsaved file, another
    engine's, a stamped version or ``VOXGI_NO_WARMUP_PROCESS`` start none."""
    from voxgi.render import kernel_warmup, warmup_process

    started = []

    class Child:
        def __init__(self, code):
            self.code = code

        def poll(self):
            return self.code

        def kill(self):
            self.code = -9

    children = []

    def launch(blend, w, h, **_):
        started.append((blend, w, h))
        children.append(Child(None))  # running until the test says it ended
        return children[-1]

    monkeypatch.setattr(warmup_process, "launch", launch)
    processes = warmup_process.WarmupProcesses(cache_dir=str(tmp_path / "stamps"))
    monkeypatch.setattr(warmup_process, "processes", processes)
    scene = bpy.context.scene
    scene.render.engine = "VOXGI"
    assert not kernel_warmup.start_process(scene, bpy.context)  # not saved yet
    blend = saved_demo(tmp_path / "demo.blend")
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    assert not kernel_warmup.start_process(scene, bpy.context)
    scene.render.engine = "VOXGI"
    monkeypatch.setenv(warmup_process.DISABLE, "1")
    assert not kernel_warmup.start_process(scene, bpy.context)
    monkeypatch.delenv(warmup_process.DISABLE)
    assert kernel_warmup.start_process(scene, bpy.context)
    # at the size of the file's largest 3D view (where Rendered mode draws)
    views = [(r.width, r.height) for w in bpy.context.window_manager.windows
             for a in w.screen.areas if a.type == "VIEW_3D" for r in a.regions
             if r.type == "WINDOW"] or [kernel_warmup.DEFAULT_REGION]
    assert started == [(blend, *max(views, key=lambda s: s[0] * s[1]))]
    assert "in the background" in processes.status()  # the sidebar says so while it runs
    assert not kernel_warmup.start_process(scene, bpy.context)  # one at a time
    children[-1].code = 0
    assert processes.status() == ""
    assert not processes.poll()  # the child said it was done: its stamp written
    assert warmup_process.stamp_path(blend, processes.cache_dir).exists()
    assert not kernel_warmup.start_process(scene, bpy.context)  # this version is warmed
    bpy.ops.wm.save_as_mainfile(filepath=blend)  # a new version of the file
    assert kernel_warmup.start_process(scene, bpy.context)
    assert len(started) == 2
    children[-1].code = 0
    assert not processes.poll()
    # a child that failed writes no stamp, and is not started again in this session
    monkeypatch.setattr(warmup_process, "launch", lambda *a, **k: Child(1))
    other = str(tmp_path / "other.blend")
    bpy.ops.wm.save_as_mainfile(filepath=other)
    scene = bpy.context.scene
    assert kernel_warmup.start_process(scene, bpy.context)
    assert not processes.poll()
    assert not warmup_process.stamp_path(other, processes.cache_dir).exists()
    assert not kernel_warmup.start_process(scene, bpy.context)


def test_the_child_runs_at_the_lowest_priority(tmp_path):
    """The child lowers its own priority first thing (no ``preexec_fn``: that would fork the
    whole Blender process on the main thread), so the user's session keeps the cores."""
    import time

    from voxgi.render import warmup_process

    if not sys.platform.startswith("linux"):
        return  # /proc is Linux's; elsewhere the child's priority is not read here
    blend = saved_demo(tmp_path / "demo.blend")
    child = warmup_process.launch(blend, *REGION, env=shader_cache_env(tmp_path / "cache"))
    try:
        nice = None
        for _ in range(200):  # until its first step ran
            time.sleep(0.05)
            nice = int(open(f"/proc/{child.pid}/stat").read().rsplit(")", 1)[1].split()[16])
            if nice == 19 or child.poll() is not None:
                break
        assert nice == 19
    finally:
        child.kill()
        child.wait()

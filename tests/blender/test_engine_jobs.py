"""The engine worker: cancel, supersede, a stress run while the scene is edited, no bpy in the
worker, and a clean unregister.

Timers registered with ``bpy.app.timers`` never fire in the ``bpy`` module (no event loop, see
``test_timers_do_not_fire_without_an_event_loop``), so these tests apply finished jobs with
``engine_jobs.drain()`` / ``wait_idle()``. ``engine_jobs.synchronous = False`` makes the
operator behave as in an interactive session (return right after submitting).
"""
from __future__ import annotations

import ast
import dataclasses
import importlib
import math
import pathlib
import sys
import threading
import time
import types

import bpy
import mathutils
import numpy as np
import pytest
import scenes

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
BLENDER_MODULES = {"bpy", "bpy_types", "_bpy", "bpy_extras", "mathutils", "bmesh", "gpu",
                   "gpu_extras", "bl_math", "blf", "aud", "imbuf", "idprop", "freestyle"}
TIMEOUT = 30.0  # seconds before a test gives up on a job instead of hanging
EDITS = 150  # main-thread edit rounds of the stress test


@pytest.fixture
def voxelize_module(voxgi):
    return importlib.import_module("voxgi.operators.voxelize")


@pytest.fixture
def mesh_caches(voxgi):
    return importlib.import_module("voxgi.voxgi_addon.voxelize.scene_caches")


@pytest.fixture
def errors(voxgi):
    return importlib.import_module("voxgi.voxgi_addon.errors")


def scene_name():
    return bpy.context.scene.name_full


def state(session):
    return session.scene_session(scene_name())


def wait_applied(jobs, job):
    assert job.wait(TIMEOUT), f"{job} did not finish within {TIMEOUT} s"
    jobs.drain()
    assert job.state != "running"


def blocking_engine(started: threading.Event, calls: list):
    """A fake ``build_scene_caches`` that blocks until its job is cancelled."""
    def build(snapshot, base_span, cascade_count, cancel=None):
        calls.append(threading.get_ident())
        started.set()
        deadline = time.perf_counter() + TIMEOUT
        while not cancel():
            if time.perf_counter() > deadline:
                return "never cancelled"
            time.sleep(0.002)
        raise importlib.import_module("voxgi.voxgi_addon.errors").VoxGICancelled("stop")
    return build


def torus_object(name, major=64, minor=32, radius=1.0, tube=0.35, material=None):
    """A torus of ``major × minor`` quads (2·major·minor triangles), linked into the scene."""
    u = np.linspace(0, 2 * np.pi, major, endpoint=False)[:, None]
    v = np.linspace(0, 2 * np.pi, minor, endpoint=False)[None, :]
    ring = radius + tube * np.cos(v)
    vertices = np.stack([ring * np.cos(u), ring * np.sin(u), tube * np.sin(v) + 0 * u], -1)
    i, j = np.meshgrid(np.arange(major), np.arange(minor), indexing="ij")
    a = i * minor + j
    b = ((i + 1) % major) * minor + j
    c = ((i + 1) % major) * minor + (j + 1) % minor
    d = i * minor + (j + 1) % minor
    faces = np.stack([a, b, c, d], -1).reshape(-1, 4)
    obj = scenes.mesh_object(name, vertices.reshape(-1, 3), faces.tolist())
    if material is not None:
        obj.data.materials.append(material)
    return obj


def assert_same_caches(got, expected):
    """Same cascades, voxel counts and packed words for every (mesh key, cascade)."""
    assert [(s.cascade, s.voxel_count, s.nbytes) for s in got.cascade_stats] == \
        [(s.cascade, s.voxel_count, s.nbytes) for s in expected.cascade_stats]
    assert got.caches.keys() == expected.caches.keys()
    for key, caches in expected.caches.items():
        for mine, theirs in zip(got.caches[key], caches, strict=True):
            assert (mine is None) == (theirs is None), key
            if theirs is None:
                continue
            assert mine.voxel_count == theirs.voxel_count, key
            for name in ("origin_cell", "dims", "positions", "normals", "colors", "weights",
                         "bone_indices"):
                a, b = getattr(mine, name), getattr(theirs, name)
                assert (a is None and b is None) or np.array_equal(a, b), (key, name)


def test_timers_do_not_fire_without_an_event_loop():
    """The fact the other tests rely on: in the bpy module a due timer never runs."""
    fired = []

    def tick():
        fired.append(1)
        return 0.001

    bpy.app.timers.register(tick, first_interval=0.0)
    try:
        time.sleep(0.05)
        bpy.context.view_layer.update()
        assert bpy.app.background and fired == []
    finally:
        bpy.app.timers.unregister(tick)


def test_background_mode_runs_the_job_before_the_operator_returns(jobs, session):
    assert jobs.synchronous is None and bpy.app.background
    scenes.quad_object("Quad")
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    job = jobs.latest_job(scene_name())
    assert job.state == "done" and job.finished
    assert state(session).caches is job.result and state(session).caches.total_voxels > 0
    assert not jobs.timer_registered()


def test_cancel_keeps_the_previous_caches(interactive, voxelize_module, session, monkeypatch):
    jobs = interactive
    scenes.quad_object("Quad")
    jobs.synchronous = True
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    previous, previous_report = state(session).caches, list(state(session).last_report)
    assert previous is not None
    jobs.synchronous = False
    with pytest.raises(RuntimeError, match="No VoxGI job is running"):
        bpy.ops.voxgi.cancel_job()

    started, calls = threading.Event(), []
    monkeypatch.setattr(voxelize_module, "build_scene_caches", blocking_engine(started, calls))
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}  # returns at once
    job = jobs.running_job(scene_name())
    assert job is not None and job.state == "running" and jobs.timer_registered()
    assert started.wait(TIMEOUT)
    time.sleep(0.05)
    jobs.drain()
    assert job.state == "running" and state(session).last_report == previous_report
    assert job.elapsed > 0

    assert bpy.ops.voxgi.cancel_job.poll()
    assert bpy.ops.voxgi.cancel_job() == {"FINISHED"}
    wait_applied(jobs, job)

    assert job.state == "cancelled" and job.result is None
    assert state(session).caches is previous
    assert state(session).last_report == [("INFO", "Voxelization cancelled; previous caches kept")]
    assert calls and calls[0] != threading.main_thread().ident
    assert jobs.running_job(scene_name()) is None and not jobs.timer_registered()
    assert not bpy.ops.voxgi.cancel_job.poll()


def test_cancel_discards_a_result_returned_after_the_request(interactive):
    jobs = interactive
    started, release, outcomes = threading.Event(), threading.Event(), []

    def stubborn(cancel):
        started.set()
        release.wait(TIMEOUT)
        return "result"

    job = jobs.submit("S", stubborn, on_done=outcomes.append,
                      on_cancel=lambda: outcomes.append("cancelled"))
    assert started.wait(TIMEOUT)
    assert jobs.cancel("S") is job and job.cancel_requested
    release.set()  # the job ignores cancel() and returns a result anyway
    wait_applied(jobs, job)
    assert job.state == "cancelled" and job.result is None and outcomes == ["cancelled"]


def test_a_newer_submission_supersedes_the_older(interactive):
    jobs = interactive
    started, release, applied, cancelled = threading.Event(), threading.Event(), [], []

    def slow(cancel):
        started.set()
        release.wait(TIMEOUT)  # ignores cancel(): its result must still be dropped
        return "slow"

    old = jobs.submit("S", slow, on_done=applied.append, on_cancel=lambda: cancelled.append("old"))
    assert started.wait(TIMEOUT)
    new = jobs.submit("S", lambda cancel: "fast", on_done=applied.append,
                      on_cancel=lambda: cancelled.append("new"))
    other = jobs.submit("Other scene", lambda cancel: "other", on_done=applied.append)
    assert old.cancel_requested and old.superseded and not new.cancel_requested
    assert jobs.running_job("S") is new and jobs.latest_job("S") is new
    release.set()
    assert jobs.wait_idle(TIMEOUT)

    assert applied == ["fast", "other"] and cancelled == []
    assert (old.state, new.state, other.state) == ("cancelled", "done", "done")
    assert new.result == "fast" and old.result is None


def test_voxelizing_again_supersedes_the_running_voxelization(interactive, voxelize_module,
                                                              mesh_caches, session, monkeypatch):
    jobs = interactive
    scenes.quad_object("Quad")
    started, release = threading.Event(), threading.Event()
    real = mesh_caches.build_scene_caches
    stale = real(importlib.import_module("voxgi.blender.snapshot.scene").take_snapshot(
        bpy.context, bpy.context.evaluated_depsgraph_get()), 0.5, 1)

    def first_slow(snapshot, base_span, cascade_count, cancel=None):
        if not started.is_set():
            started.set()
            release.wait(TIMEOUT)
            return stale  # a finished result of the superseded run
        return real(snapshot, base_span, cascade_count, cancel=cancel)

    monkeypatch.setattr(voxelize_module, "build_scene_caches", first_slow)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    first = jobs.running_job(scene_name())
    assert started.wait(TIMEOUT)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    second = jobs.running_job(scene_name())
    assert second is not first and first.superseded
    release.set()
    assert jobs.wait_idle(TIMEOUT)

    assert (first.state, second.state) == ("cancelled", "done")
    assert state(session).caches is second.result and state(session).caches is not stale
    assert len(state(session).caches.cascade_stats) == bpy.context.scene.voxgi.cascade_count
    assert not any("cancelled" in m for _, m in state(session).last_report)


def test_a_failing_job_reports_an_error_and_keeps_the_caches(interactive, voxelize_module,
                                                             session, monkeypatch):
    jobs = interactive
    scenes.quad_object("Quad")
    jobs.synchronous = True
    bpy.ops.voxgi.voxelize()
    previous = state(session).caches

    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(voxelize_module, "build_scene_caches", broken)
    with pytest.raises(RuntimeError, match="ZeroDivisionError: boom"):  # synchronous: ERROR report
        bpy.ops.voxgi.voxelize()
    job = jobs.latest_job(scene_name())
    assert job.state == "failed" and isinstance(job.error, ZeroDivisionError)
    assert state(session).caches is previous


def test_stress_worker_voxelizes_while_the_main_thread_edits_the_scene(
        interactive, voxelize_module, mesh_caches, snapshot_module, session, monkeypatch):
    """The worker voxelizes a ~4.5k-triangle snapshot (skinned demo objects included) over and
    over while the main thread adds, moves and deletes objects, rewrites vertices and
    materials and takes snapshots; every worker run equals a main-thread run on the snapshot
    taken before the edits."""
    jobs = interactive
    bpy.ops.voxgi.add_demo_scene()
    gold = scenes.principled("Gold", (1.0, 0.8, 0.2), roughness=0.2)
    torus = torus_object("Torus", material=gold)
    settings = bpy.context.scene.voxgi
    settings.span_mode = "MANUAL"  # the reference below voxelizes at this base span
    settings.base_span, settings.cascade_count = 0.04, 2
    before = snapshot_module.take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
    assert sum(len(m.triangles) for m in before.meshes.values()) > 4000
    reference = mesh_caches.build_scene_caches(before, settings.base_span, settings.cascade_count)

    real = mesh_caches.build_scene_caches
    editing, edits_done, builds, spans = threading.Event(), threading.Event(), [], []

    def repeated(snapshot, base_span, cascade_count, cancel=None):
        editing.wait(TIMEOUT)
        while True:
            start = time.perf_counter()
            builds.append(real(snapshot, base_span, cascade_count, cancel=cancel))
            spans.append((start, time.perf_counter()))
            if edits_done.is_set() or len(builds) >= 100:
                return builds[-1]

    monkeypatch.setattr(voxelize_module, "build_scene_caches", repeated)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    job = jobs.running_job(scene_name())
    assert job is not None

    editing.set()
    edit_times, added = [], []
    positions = np.empty(len(torus.data.vertices) * 3, np.float32)
    torus.data.vertices.foreach_get("co", positions)
    for i in range(EDITS):
        edit_times.append(time.perf_counter())
        added.append(scenes.quad_object(f"Added {i}", size=0.2 + 0.001 * i))
        added[-1].location = (math.sin(i), math.cos(i), 0.01 * i)
        torus.location.x += 0.05
        torus.rotation_euler.z += 0.1
        positions *= 1.001  # rewrite the mesh the snapshot was read from
        torus.data.vertices.foreach_set("co", positions)
        torus.data.update()
        bsdf = gold.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (i / EDITS, 0.5, 1 - i / EDITS, 1.0)
        torus.data.materials[0] = scenes.principled(f"Mat {i}", (0.1, 0.2, i / EDITS))
        if i % 3 == 2:  # delete an object and its mesh
            doomed = added.pop(0)
            mesh = doomed.data
            bpy.data.objects.remove(doomed)
            bpy.data.meshes.remove(mesh)
        if i == EDITS // 2:
            bpy.data.objects.remove(bpy.data.objects["Rotating Sphere"])
        bpy.context.view_layer.update()
        if i % 10 == 0:
            snapshot_module.take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
    edit_times.append(time.perf_counter())
    edits_done.set()
    wait_applied(jobs, job)

    assert job.state == "done", job.error
    assert builds, "the worker never ran"
    # Overlap: the worker was voxelizing while the main thread edited.
    assert any(start < t < end for start, end in spans for t in edit_times) or \
        any(edit_times[0] < start < edit_times[-1] for start, _ in spans)
    for build in builds:
        assert_same_caches(build, reference)
    assert state(session).caches is job.result
    assert_same_caches(state(session).caches, reference)
    assert state(session).snapshot_summary["objects"] == len(before.objects)
    assert "Rotating Sphere" not in bpy.data.objects  # the edits did happen


def _blender_objects(value, path="snapshot", seen=None):
    """Paths inside ``value`` (dataclasses, containers) that hold Blender-owned objects."""
    seen = set() if seen is None else seen
    if id(value) in seen:
        return []
    seen.add(id(value))
    if isinstance(value, (bpy.types.bpy_struct, bpy.types.bpy_prop_collection,
                          mathutils.Matrix, mathutils.Vector, mathutils.Quaternion,
                          mathutils.Euler, mathutils.Color)):
        return [path]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        items = [(f.name, getattr(value, f.name)) for f in dataclasses.fields(value)]
    elif isinstance(value, dict):
        items = [(repr(k), v) for k, v in value.items()]
    elif isinstance(value, (list, tuple)):
        items = list(enumerate(value))
    else:
        return []
    return [p for name, v in items for p in _blender_objects(v, f"{path}.{name}", seen)]


def test_the_worker_never_touches_bpy(interactive, voxelize_module, mesh_caches, monkeypatch):
    """Every Python or C call the engine makes on the worker is traced: none reaches Blender's
    modules, a bpy_struct method or add-on code that may use bpy, and the job closes over no
    Blender object. (Attribute reads and C slots such as ``len()`` are not traced: the import
    scan below and the no-Blender-object check of the job's inputs cover those.)"""
    jobs = interactive
    bpy.ops.voxgi.add_demo_scene()
    bpy.context.scene.voxgi.span_mode = "MANUAL"  # a coarse span keeps the traced run short
    bpy.context.scene.voxgi.base_span, bpy.context.scene.voxgi.cascade_count = 0.2, 2
    real = mesh_caches.build_scene_caches
    seen, bad, threads, snapshots = set(), [], [], []

    def module_of(frame_or_func):
        if isinstance(frame_or_func, types.FrameType):
            return frame_or_func.f_globals.get("__name__", "")
        owner = getattr(frame_or_func, "__self__", None)
        names = [getattr(frame_or_func, "__module__", None) or "",
                 type(owner).__module__ if owner is not None else ""]
        if isinstance(owner, types.ModuleType):
            names.append(owner.__name__)
        return next((n for n in names if n.split(".")[0] in BLENDER_MODULES), names[0])

    def hook(frame, event, arg):
        if event not in ("call", "c_call"):
            return
        name = module_of(frame if event == "call" else arg)
        seen.add(name)
        owner = getattr(arg, "__self__", None) if event == "c_call" else None
        if (name.split(".")[0] in BLENDER_MODULES or name.startswith(("voxgi.operators", "voxgi.ui",
                                                                       "voxgi.blender", "voxgi.render"))
                or isinstance(owner, (bpy.types.bpy_struct, bpy.types.bpy_prop_collection))):
            bad.append((event, name, getattr(arg, "__qualname__", None) or frame.f_code.co_name))

    def traced(snapshot, base_span, cascade_count, cancel=None):
        threads.append(threading.current_thread())
        snapshots.append(snapshot)
        sys.setprofile(hook)  # this thread only
        try:
            return real(snapshot, base_span, cascade_count, cancel=cancel)
        finally:
            sys.setprofile(None)

    monkeypatch.setattr(voxelize_module, "build_scene_caches", traced)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    job = jobs.running_job(scene_name())
    closure = [cell.cell_contents for cell in job.fn.__closure__ or ()]
    assert _blender_objects(closure, "job closure") == []
    wait_applied(jobs, job)

    assert job.state == "done", job.error
    assert threads[0] is not threading.main_thread() and threads[0].daemon
    assert _blender_objects(snapshots[0]) == []
    assert {"voxgi.voxgi_addon.voxelize.scene_caches", "voxgi.voxgi_addon.voxelize.surface"} <= seen  # traced
    assert bad == []


def test_engine_modules_do_not_import_blender(voxgi):
    sources = sorted((REPO_ROOT / "voxgi_addon").rglob("*.py"))
    assert len(sources) >= 5
    for path in sources:
        depth = len(path.relative_to(REPO_ROOT / "voxgi_addon").parts)  # 1 = a top-level module
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [("." * node.level) + (node.module or "")]
            else:
                continue
            for name in names:
                assert name.split(".")[0] not in BLENDER_MODULES, (path.name, name)
                level = len(name) - len(name.lstrip("."))
                assert level <= depth, (path.name, name)  # nothing from the add-on above it
    loaded = {n: m for n, m in sys.modules.items() if n.startswith("voxgi.voxgi_addon")}
    assert "voxgi.voxgi_addon.voxelize.scene_caches" in loaded
    for name, module in loaded.items():
        for attr, value in vars(module).items():
            if isinstance(value, types.ModuleType):
                assert value.__name__.split(".")[0] not in BLENDER_MODULES, (name, attr)


def test_engine_checks_cancel_between_cascades(voxgi, mesh_caches, errors, snapshot_module):
    scenes.quad_object("Quad")
    snapshot = snapshot_module.take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
    asked = []

    def cancel():  # False before the (only) mesh, True at its second cascade
        asked.append(1)
        return len(asked) > 2

    with pytest.raises(errors.VoxGICancelled):
        mesh_caches.build_scene_caches(snapshot, 0.1, 3, cancel=cancel)
    assert len(asked) == 3


def test_timer_runs_only_while_a_job_runs(interactive):
    jobs = interactive
    assert not jobs.timer_registered()
    release = threading.Event()
    job = jobs.submit("S", lambda cancel: release.wait(TIMEOUT))
    assert jobs.timer_registered()
    assert jobs._tick() == jobs.TICK_SECONDS  # what Blender would call: keeps ticking
    release.set()
    assert job.wait(TIMEOUT)
    assert jobs._tick() is None and job.state == "done"  # idle: Blender drops the timer
    jobs.drain()
    assert not jobs.timer_registered()


def test_file_load_drops_running_jobs_silently(interactive):
    jobs = interactive
    outcomes = []
    job = jobs.submit("Scene", lambda cancel: "x", on_done=outcomes.append,
                      on_cancel=lambda: outcomes.append("cancelled"))
    bpy.ops.wm.read_factory_settings(use_empty=True)  # load_pre cancels it
    assert jobs.wait_idle(TIMEOUT)
    assert job.state == "cancelled" and outcomes == []


class _Layout:
    """Records UILayout calls of a panel's draw()."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        def call(*args, **kwargs):
            self.log.append((name, args, kwargs))
            return _Layout(self.log)
        return call


def _draw_panel(voxgi):
    log = []
    panel = importlib.import_module("voxgi.ui.panel").VOXGI_PT_main
    panel.draw(types.SimpleNamespace(layout=_Layout(log)), bpy.context)
    labels = [kw.get("text", "") for name, _, kw in log if name == "label"]
    operators = [args[0] for name, args, _ in log if name == "operator"]
    return labels, operators


def test_panel_shows_the_running_job_then_the_outcome(interactive, voxgi, voxelize_module,
                                                      monkeypatch):
    jobs = interactive
    scenes.quad_object("Quad")
    started = threading.Event()
    monkeypatch.setattr(voxelize_module, "build_scene_caches", blocking_engine(started, []))
    bpy.ops.voxgi.voxelize()
    labels, operators = _draw_panel(voxgi)
    assert "voxgi.cancel_job" in operators
    assert any(t.startswith("Voxelizing… ") and t.endswith(" s") for t in labels)
    job = jobs.cancel(scene_name())
    labels, _ = _draw_panel(voxgi)
    assert any(t.startswith("Cancelling… ") for t in labels)
    wait_applied(jobs, job)
    labels, operators = _draw_panel(voxgi)
    assert "voxgi.cancel_job" not in operators
    assert "Voxelization cancelled; previous caches kept" in labels


def test_unregister_cancels_and_joins_a_running_job(interactive, voxgi):
    jobs = interactive
    started, outcomes = threading.Event(), []

    def blocking(cancel):
        started.set()
        while not cancel():
            time.sleep(0.002)
        raise importlib.import_module("voxgi.voxgi_addon.errors").VoxGICancelled("stop")

    job = jobs.submit("S", blocking, on_cancel=lambda: outcomes.append("cancelled"))
    assert started.wait(TIMEOUT) and jobs.timer_registered()
    worker = jobs._runner.thread
    try:
        start = time.perf_counter()
        voxgi.unregister()
        assert time.perf_counter() - start < jobs.JOIN_TIMEOUT
        assert not worker.is_alive() and job.finished and job.state == "cancelled"
        assert outcomes == []  # the session is gone: no callbacks after unregister
        assert not jobs.timer_registered() and jobs.running_job("S") is None
        with pytest.raises(RuntimeError, match="not registered"):
            jobs.submit("S", lambda cancel: None)
    finally:
        voxgi.register()
    again = jobs.submit("S", lambda cancel: "after")  # a fresh worker
    assert jobs.wait_idle(TIMEOUT) and again.result == "after"


def test_unregister_gives_up_on_a_job_that_ignores_cancel(interactive, voxgi, monkeypatch):
    jobs = interactive
    monkeypatch.setattr(jobs, "JOIN_TIMEOUT", 0.2)
    started, release = threading.Event(), threading.Event()

    def stubborn(cancel):
        started.set()
        release.wait(TIMEOUT)
        return "late"

    job = jobs.submit("S", stubborn)
    assert started.wait(TIMEOUT)
    worker = jobs._runner.thread
    try:
        start = time.perf_counter()
        voxgi.unregister()
        # It returned long before the stubborn job would let go (TIMEOUT), leaving it running.
        assert time.perf_counter() - start < TIMEOUT / 3 and worker.is_alive() and worker.daemon
    finally:
        release.set()
        voxgi.register()
    worker.join(TIMEOUT)
    assert not worker.is_alive() and job.state == "running"  # its outcome went nowhere


def test_stress_viewport_job_while_the_main_thread_edits_the_scene(interactive, monkeypatch):
    """The viewport's job (caches → cascades → injection → octree → atlas) on the worker while
    the main thread edits the scene 200 times (move, add, delete objects, change materials)
    and, every 50 edits, hands the updates to ``LiveGI.update`` as ``view_update`` would,
    superseding the running job. Every job ends done or cancelled, nothing raises, and the
    applied result equals a synchronous run on the same snapshot."""
    jobs = interactive
    viewport_session = importlib.import_module("voxgi.blender.viewport_session")
    incremental = importlib.import_module("voxgi.voxgi_addon.voxelize.incremental")
    staged_gi = importlib.import_module("voxgi.voxgi_addon.gi.incremental")
    settings_module = importlib.import_module("voxgi.blender.settings")
    records_from_depsgraph = importlib.import_module("voxgi.blender.updates").records_from_depsgraph
    bpy.ops.voxgi.add_demo_scene()
    gold = scenes.principled("Gold", (1.0, 0.8, 0.2), roughness=0.2)
    torus = torus_object("Torus", material=gold)
    scene = bpy.context.scene
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.08, 2, "32"
    live = viewport_session.live_gi(scene_name())

    real = incremental.refresh_caches
    editing, edits_done, runs = threading.Event(), threading.Event(), []

    def slow_refresh(store, snapshot, base_span, count, cancel=None, progress=None):
        """Keeps the worker busy with real voxelizations until the edits are over (or it is
        superseded), the way a big scene would."""
        editing.wait(TIMEOUT)
        while True:
            real(incremental.CacheStore(), snapshot, base_span, count, cancel, progress)
            runs.append(threading.current_thread())
            if edits_done.is_set() or cancel():
                return real(store, snapshot, base_span, count, cancel, progress)

    monkeypatch.setattr(viewport_session, "refresh_caches", slow_refresh)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    collected = []

    def handler(scene, depsgraph):
        collected.extend(records_from_depsgraph(depsgraph, live.index))

    live.update(scene, depsgraph)
    submitted = [jobs.latest_job(scene_name())]
    assert submitted[0].state == "running"
    bpy.app.handlers.depsgraph_update_post.append(handler)
    editing.set()
    added = []
    try:
        for i in range(200):
            added.append(scenes.quad_object(f"Added {i}", size=0.2 + 0.001 * i))
            added[-1].location = (math.sin(i), math.cos(i), 0.01 * i)
            torus.location.x += 0.01
            torus.rotation_euler.z += 0.1
            gold.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = \
                (i / 200, 0.5, 1 - i / 200, 1.0)
            torus.data.materials[0] = scenes.principled(f"Mat {i}", (0.1, 0.2, i / 200))
            if i % 3 == 2:
                doomed = added.pop(0)
                mesh = doomed.data
                bpy.data.objects.remove(doomed)
                bpy.data.meshes.remove(mesh)
            if i == 100:
                bpy.data.objects.remove(bpy.data.objects["Rotating Sphere"])
            bpy.context.view_layer.update()
            if i % 50 == 49:  # what view_update would do: supersedes the running job
                live.update(scene, depsgraph, collected[:])
                collected.clear()
                submitted.append(jobs.latest_job(scene_name()))
            jobs.drain()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
        edits_done.set()
    assert jobs.wait_idle(TIMEOUT * 4)

    assert runs and all(t is not threading.main_thread() for t in runs)
    assert len({id(j) for j in submitted}) >= 4
    assert {j.state for j in submitted} <= {"done", "cancelled"}
    assert submitted[-1].state == "done" and live.error == ""
    assert all(j.state == "cancelled" for j in submitted[:-1] if j is not submitted[-1])
    result = submitted[-1].result
    # The synchronous run on the same snapshot (the job's, camera included).
    settings = scene.voxgi
    expected = real(incremental.CacheStore(), result.snapshot, settings.base_span,
                    settings.cascade_count)
    assert_same_caches(result.caches, expected.caches)
    state = staged_gi.update_gi_stages(result.snapshot, expected.caches,
                                       settings_module.gi_settings(settings), None,
                                       {"transform"}).state
    for mine, theirs in zip(result.staged.state.cascades, state.cascades, strict=True):
        assert np.array_equal(mine.cells, theirs.cells)
    for mine, theirs in zip(result.staged.state.radiance, state.radiance, strict=True):
        np.testing.assert_allclose(mine, theirs, atol=1e-6)
    assert live.staged is result.staged and live.snapshot is result.snapshot
    assert len(result.snapshot.objects) == len(bpy.context.view_layer.objects) - 3  # - rig, light, camera


def test_the_worker_runs_below_the_main_thread(interactive):
    """On Linux the worker thread (and the viewport's preparing thread) runs at a lower CPU
    priority than the main thread, so its numpy does not take the cores the view's draws
    need (docs/gi_pipeline.md "Worker threads below the main
    thread, steps timed to their rasters' end")."""
    import os
    import sys
    import threading

    if not sys.platform.startswith("linux"):
        return  # elsewhere the threads keep the process's priority (nothing to check)
    seen = []
    job = interactive.submit("scene", lambda cancel: seen.append(
        os.getpriority(os.PRIO_PROCESS, threading.get_native_id())), label="probe")
    assert interactive.wait_idle(30.0) and job.state == "done"
    main = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    assert seen == [min(19, main + interactive.BACKGROUND_NICE)]

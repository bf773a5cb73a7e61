"""The viewport's robustness: register/unregister cycles leave nothing behind, file loads and
undo/redo never leave stale caches, cancel and failures keep the previous results, deleting an
object under a running job is harmless, progress lines are rate-limited, panels and buttons."""
from __future__ import annotations

import dataclasses
import importlib
import threading
import types

import bpy
import numpy as np
import pytest
import scenes

TIMEOUT = 60.0
HANDLER_LISTS = [name for name in dir(bpy.app.handlers)
                 if isinstance(getattr(bpy.app.handlers, name), list)]


@pytest.fixture
def viewport_session(voxgi):
    return importlib.import_module("voxgi.blender.viewport_session")


def two_boxes():
    scene = bpy.context.scene
    h = 0.5
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    a = scenes.mesh_object("Box A", corners, faces)
    b = scenes.mesh_object("Box B", corners, faces)
    b.location = (2.0, 0.0, 0.0)
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.location = (0.0, 0.0, 3.0)
    scenes.link(light)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (1.0, -6.0, 1.0)
    camera.rotation_euler = (1.4, 0.0, 0.0)
    scenes.link(camera)
    scene.camera = camera
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.1, 2, "32"
    return scene, a, b


def counts():
    jobs = importlib.import_module("voxgi.blender.jobs")
    keyconfig = bpy.context.window_manager.keyconfigs.addon
    keymap = keyconfig.keymaps.get("3D View") if keyconfig else None
    return {
        "handlers": {name: len(getattr(bpy.app.handlers, name)) for name in HANDLER_LISTS},
        "timer": bpy.app.timers.is_registered(jobs._tick),
        "keymap items": 0 if keymap is None else sum(
            item.idname == "voxgi.cancel_job" for item in keymap.keymap_items),
    }


def test_enable_disable_20_times_leaves_no_handlers_timers_callbacks_or_gpu_objects(voxgi, interactive):
    from voxgi.render.gpu_context import ensure_gpu_context

    assert ensure_gpu_context()[0]
    voxgi.unregister()
    start = counts()
    voxgi.register()
    registered = counts()
    assert registered["keymap items"] == start["keymap items"] + 1
    assert registered["handlers"]["undo_post"] == start["handlers"]["undo_post"] + 1
    scene, _, _ = two_boxes()
    for cycle in range(20):
        ui_draw = importlib.import_module("voxgi.ui.debug_draw")
        handle = ui_draw._handle
        assert handle is not None
        if cycle % 5 == 0:  # leave GPU objects, a running job and its timer to clean up
            viewport = importlib.import_module("voxgi.render.viewport")
            debug = importlib.import_module("voxgi.render.debug_draw")
            session = importlib.import_module("voxgi.blender.viewport_session")
            live = session.live_gi(scene.name_full)
            interactive.synchronous = True
            live.update(scene, bpy.context.evaluated_depsgraph_get())
            interactive.synchronous = False
            renderer = viewport.ViewportRenderer()
            small = dataclasses.replace(live.snapshot.camera, resolution=(16, 12))
            renderer.trace(live, scene, small, "key", "Combined")
            drawer = debug.DebugDrawer()
            drawer.prepare(live.staged.state, "VOXELS", 0, 0, "ALBEDO")
            ui_draw._drawers[scene.name_full] = drawer
            release = threading.Event()
            interactive.submit(scene.name_full, lambda cancel: release.wait(TIMEOUT))
            assert interactive.timer_registered()
            assert renderer.texture is not None and drawer.instances is not None
        voxgi.unregister()
        if cycle % 5 == 0:
            release.set()
            assert renderer.texture is None and len(viewport._renderers) == 0 or \
                all(r.texture is None for r in viewport._renderers)
            assert drawer.instances is None and debug._shader is None
            assert not ui_draw._drawers
        assert counts() == start, cycle
        with pytest.raises(ValueError):  # the draw callback was removed
            bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
        voxgi.register()
        assert counts() == registered, cycle


def test_loading_a_file_clears_the_viewport_session(viewport_session):
    scene, _, _ = two_boxes()
    name = scene.name_full
    live = viewport_session.live_gi(name)
    live.update(scene, bpy.context.evaluated_depsgraph_get())
    assert live.staged is not None
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert viewport_session.peek_live_gi(name) is None
    assert viewport_session.current_state(bpy.context.scene.name_full) is None


def test_undo_and_redo_never_leave_stale_caches(viewport_session):
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    scene, a, _ = two_boxes()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = viewport_session.live_gi(scene.name_full)
    live.update(scene, depsgraph)
    original = live.staged.caches.caches["Box A"]
    bpy.ops.ed.undo_push(message="before the edit")
    co = np.empty(len(a.data.vertices) * 3, np.float32)
    a.data.vertices.foreach_get("co", co)
    a.data.vertices.foreach_set("co", co * 1.5)
    a.data.update()
    bpy.ops.ed.undo_push(message="scaled Box A's vertices")
    live.update(scene, depsgraph, [])  # records aside: undo/redo below is what matters
    live.rescan = "test"
    live.update(scene, depsgraph, [])
    assert live.stats.voxelized == ["Box A"]
    edited = live.staged.caches.caches["Box A"]

    def fresh():
        snap = take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
        settings = bpy.context.scene.voxgi  # undo replaced the scene's Python object
        return build_scene_caches(snap, settings.base_span, settings.cascade_count)

    for step, expected in ((bpy.ops.ed.undo, original), (bpy.ops.ed.redo, edited)):
        assert step() == {"FINISHED"}
        assert live.rescan  # undo_post / redo_post
        live.update(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), [])
        assert live.stats.triggers == ("undo / redo",)
        assert live.stats.voxelized == []  # the earlier version's caches, found by fingerprint
        assert live.staged.caches.caches["Box A"] is expected
        reference = fresh()
        assert [s.voxel_count for s in live.staged.caches.cascade_stats] == \
            [s.voxel_count for s in reference.cascade_stats]
        for mine, theirs in zip(live.staged.caches.caches["Box A"], reference.caches["Box A"]):
            assert np.array_equal(mine.positions, theirs.positions)


def test_a_failing_job_shows_its_error_and_the_addon_stays_usable(viewport_session, monkeypatch):
    scene, _, _ = two_boxes()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = viewport_session.live_gi(scene.name_full)
    live.update(scene, depsgraph)
    previous = live.staged

    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    real = viewport_session.update_gi_stages
    monkeypatch.setattr(viewport_session, "update_gi_stages", broken)
    bpy.data.objects["Box B"].location.x += 0.5
    live.rescan = "test"
    live.update(scene, depsgraph, [])
    assert live.error == "ZeroDivisionError: boom" and live.staged is previous
    labels = draw_panel("VOXGI_PT_viewport")[0]
    assert "ZeroDivisionError: boom" in labels
    monkeypatch.setattr(viewport_session, "update_gi_stages", real)
    live.rescan = "test"
    live.update(scene, depsgraph, [])
    assert live.error == "" and live.staged is not previous


def test_cancel_keeps_the_previous_results(viewport_session, interactive, monkeypatch):
    scene, _, _ = two_boxes()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = viewport_session.live_gi(scene.name_full)
    interactive.synchronous = True
    live.update(scene, depsgraph)
    interactive.synchronous = False
    previous, generation = live.staged, live.generation
    started, checks = threading.Event(), []
    real = viewport_session.refresh_caches

    def slow(store, snapshot, base_span, count, cancel=None, progress=None):
        started.set()
        while not cancel():
            checks.append(1)
            threading.Event().wait(0.005)
        return real(store, snapshot, base_span, count, cancel, progress)

    monkeypatch.setattr(viewport_session, "refresh_caches", slow)
    live.rescan = "test"
    live.update(scene, depsgraph, [])
    job = live.running
    assert job is not None and started.wait(TIMEOUT)
    labels, operators, _ = draw_panel("VOXGI_PT_viewport")
    assert "voxgi.cancel_job" in operators
    assert any(t.startswith("Updating viewport GI ") and t.endswith(" s)") for t in labels)
    assert bpy.ops.voxgi.cancel_job() == {"FINISHED"}  # what Esc calls
    assert job.wait(TIMEOUT)
    interactive.drain()
    assert job.state == "cancelled" and live.staged is previous and live.generation == generation
    assert live.error == "" and live.pending is None and checks


def test_deleting_an_object_while_its_job_runs_loses_nothing(viewport_session, interactive,
                                                            monkeypatch):
    scene, _, b = two_boxes()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = viewport_session.live_gi(scene.name_full)
    started, release = threading.Event(), threading.Event()
    real = viewport_session.refresh_caches

    def held(*args, **kwargs):
        started.set()
        release.wait(TIMEOUT)
        return real(*args, **kwargs)

    monkeypatch.setattr(viewport_session, "refresh_caches", held)
    live.update(scene, depsgraph)
    job = live.running
    assert started.wait(TIMEOUT)
    mesh = b.data
    bpy.data.objects.remove(b)
    bpy.data.meshes.remove(mesh)
    bpy.context.view_layer.update()
    release.set()
    assert job.wait(TIMEOUT)
    interactive.drain()
    assert job.state == "done" and live.error == ""
    assert {o.name for o in live.snapshot.objects} == {"Box A", "Box B"}  # what it was given
    monkeypatch.setattr(viewport_session, "refresh_caches", real)
    interactive.synchronous = True
    from voxgi.blender.updates import records_from_depsgraph

    plan = live.update(scene, depsgraph, records_from_depsgraph(depsgraph, live.index))
    assert "objects added, removed, hidden or shown" in plan.triggers
    assert {o.name for o in live.snapshot.objects} == {"Box A"} and live.error == ""
    assert set(live.staged.caches.caches) == {"Box A"}


def test_progress_lines_at_most_once_per_second(jobs):
    now, lines = [0.0], []
    printer = jobs.ProgressPrinter("Voxelizing", clock=lambda: now[0],
                                   out=lambda text, flush: lines.append(text))
    progress = jobs.Progress()
    for t in (0.2, 0.5, 0.99, 1.0, 1.5, 1.9, 2.05, 2.1, 3.5):
        now[0] = t
        progress(t / 4, "octree")
        printer.tick(progress)
    assert lines == ["VoxGI: Voxelizing… 25% (octree), 1.0 s", "VoxGI: Voxelizing… 51% (octree), 2.0 s",
                     "VoxGI: Voxelizing… 88% (octree), 3.5 s"]


class _Layout:
    """Records UILayout calls of a panel's draw()."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        def call(*args, **kwargs):
            self.log.append((name, args, kwargs))
            return _Layout(self.log)
        return call

    def __setattr__(self, name, value):
        if name != "log":
            return
        object.__setattr__(self, name, value)


def draw_panel(name):
    log = []
    module = importlib.import_module("voxgi.ui.viewport_panel" if name == "VOXGI_PT_viewport"
                                     else "voxgi.ui.render_properties")
    getattr(module, name).draw(types.SimpleNamespace(layout=_Layout(log)), bpy.context)
    labels = [kw.get("text", "") for n, _, kw in log if n == "label"]
    operators = [args[0] for n, args, _ in log if n == "operator"]
    props = [args[1] for n, args, _ in log if n == "prop"]
    return labels, operators, props


def test_panels_show_settings_and_statistics_and_buttons_say_why(viewport_session):
    from voxgi.ui import render_properties

    scene, _, _ = two_boxes()
    for panel in render_properties.classes:
        assert panel.COMPAT_ENGINES == {"VOXGI"}
        assert panel.poll(types.SimpleNamespace(engine="VOXGI", scene=scene))
        assert not panel.poll(types.SimpleNamespace(engine="CYCLES", scene=scene))
    scene.render.engine = "CYCLES"
    with pytest.raises(RuntimeError, match="Set the render engine to VoxGI"):
        bpy.ops.voxgi.refresh_viewport()
    scene.render.engine = "VOXGI"
    assert bpy.ops.voxgi.refresh_viewport() == {"FINISHED"}
    labels, operators, props = draw_panel("VOXGI_PT_viewport")
    assert {"resolution_fraction", "viewport_pass", "debug_view", "debug_colour",
            "show_bounds"} <= set(props)
    assert "voxgi.refresh_viewport" in operators
    assert "Last update: refresh requested" in labels
    assert any(t.startswith("Stages: transform, inject, octree") for t in labels)
    assert any(t.startswith("Cascade 0 (0.1 m)") for t in labels)
    assert any(t.endswith(" nodes") for t in labels) and "Voxel caches" in labels
    assert "Voxelized: Box A, Box B" in labels
    _, _, props = draw_panel("VOXGI_PT_render_cones")
    assert {"cone_angle", "diffuse_cones", "gi_resolution", "tracer"} <= set(props)
    _, operators, props = draw_panel("VOXGI_PT_render_voxels")
    assert {"base_span", "cascade_count", "grid_resolution"} <= set(props)


def test_a_scene_without_a_camera_renders_in_a_free_view(viewport_session):
    """Cycles' Rendered view needs no scene camera (the view is its own); the view traced
    nothing and said "viewport trace failed: AttributeError: 'NoneType' object has no
    attribute 'world_matrix'" (its warm-up draws looked through the snapshot's camera). Drawn
    as a real view draws: a budgeted slice a draw, the scene prepared a step a draw."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, engine_view, gpu_ready, relative_l1

    scene, _, _ = two_boxes()
    scene.render.engine = "VOXGI"
    scene.voxgi_viewport.samples = 4

    def converged(view, window):
        engine = StandInEngine()
        for _ in range(1000):
            redraws = engine.redraws
            image = engine_view(engine, scene, bpy.context.evaluated_depsgraph_get(), view,
                                window)
            if engine.redraws == redraws:
                return engine, image
        raise AssertionError("the view never converged")

    view, window = camera_matrices(scene, bpy.context.evaluated_depsgraph_get())
    camera = scene.objects["Camera"]
    scene.collection.objects.unlink(camera)
    scene.camera = None
    gpu_ready()
    live = viewport_session.live_gi(scene.name_full)
    live.update(scene, bpy.context.evaluated_depsgraph_get())
    engine, image = converged(view, window)
    assert live.error == "" and engine.voxgi_viewport.error == ""
    assert "Converged" in engine.stats[-1]

    scene.collection.objects.link(camera)
    scene.camera = camera
    live.update(scene, bpy.context.evaluated_depsgraph_get())
    _, with_camera = converged(view, window)
    error = relative_l1(image[..., :3], with_camera[..., :3])
    print(f"free view without a camera vs with one: {error:.4f}")
    assert error < 0.03


def test_a_panoramic_camera_in_the_camera_view_says_it_is_drawn_as_perspective(viewport_session):
    """Blender hands the camera view of a panoramic camera a perspective projection, which the
    view traces; Cycles' view traces the panorama. The header says so, with what to change (F12
    stops with the same advice); a free view, or a perspective camera, adds nothing."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, engine_view, gpu_ready

    scene, _, _ = two_boxes()
    scene.render.engine = "VOXGI"
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    viewport_session.live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    engine_view(engine, scene, depsgraph, view, window, perspective="CAMERA")
    assert "panoramic" not in engine.stats[-1]
    scene.camera.data.type = "PANO"
    engine_view(engine, scene, depsgraph, view, window, perspective="CAMERA")
    assert engine.stats[-1].endswith("A panoramic camera is drawn as perspective here (F12 renders "
                                     "perspective and orthographic cameras: Camera properties > "
                                     "Lens > Type)")
    engine_view(engine, scene, depsgraph, view, window, perspective="PERSP")
    assert "panoramic" not in engine.stats[-1]


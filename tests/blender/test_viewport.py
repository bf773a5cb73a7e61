"""Live GI in the 3D view (render/viewport.py, blender/viewport_session.py).

* The viewport path — ``draw_view``, what ``view_draw`` calls — driven with the scene camera's
  view and projection matrices into a ``GPUOffScreen`` gives F12's image.
* Real depsgraph updates (collected by a ``depsgraph_update_post`` handler, as the render
  engine's ``view_update`` reads them) trigger exactly the expected stages: transforms never
  re-voxelize, a mesh edit re-voxelizes that mesh only.
"""
from __future__ import annotations

import bpy
import gpu
import numpy as np
import pytest
import scenes
from stand_in_engine import StandInEngine

WIDTH, HEIGHT = 64, 48
MOVE = {"snapshot", "transform", "inject", "octree", "trace"}
LIGHT = {"snapshot", "inject", "octree", "trace"}


def relative_l1(ours, reference):
    return float(np.abs(ours - reference).sum() / max(np.abs(reference).sum(), 1e-12))


def gpu_ready():
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    assert ready, f"no GPU context in background mode: {why}"


def live_view(scene):
    """(depsgraph, live, view, window): ``scene``'s evaluated depsgraph, its ``LiveGI``
    updated to it, and its camera's view and window matrices (a GPU context made first)."""
    from voxgi.blender.viewport_session import live_gi

    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    return (depsgraph, live, *camera_matrices(scene, depsgraph))


def bake_queued(scene):
    """Bake what the view's snapshots queued, as the bakes' timer would (a slice a tick:
    docs/gi_pipeline.md "Bakes a slice at a time"), which then takes the snapshot that reads
    the baked materials."""
    from voxgi.blender.viewport_session import live_gi, tick

    live = live_gi(scene.name_full)
    while tick() is not None:
        continue
    assert not live.bakes.pending and not live.bakes.failed


def cornell(camera_type="PERSP", light="POINT"):
    scene = bpy.context.scene
    scenes.build_test_cornell_box(scene, light=light)
    scene.voxgi.base_span = 0.07
    scene.voxgi.grid_resolution = "64"
    scene.voxgi.diffuse_cones = 8
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    # the viewport is point-sampled; a 0.01 px pixel filter makes F12's sub-pixel passes
    # point-sampled too, so the two paths can be compared pixel by pixel
    scene.cycles.filter_width = 0.01
    # one full trace per new view: the coarse first image has its own tests
    scene.voxgi_viewport.coarse_first = False
    scene.voxgi_viewport.samples = 1
    if camera_type == "ORTHO":
        scene.camera.data.type = "ORTHO"
        scene.camera.data.ortho_scale = 2.6
    return scene


def one_shot(renderer=None):
    """A renderer whose image is one sample traced in one slice (the whole image), as every
    draw traced before progressive accumulation: the tests of keys and kept images use it
    (test_viewport_progressive.py tests the slices)."""
    from voxgi.render.viewport import ViewportRenderer

    renderer = renderer or ViewportRenderer()
    renderer.progressive.fixed_pixels = 1 << 30
    renderer.progressive.stage_budget = None  # the whole slice in one draw
    bpy.context.scene.voxgi_viewport.samples = 1
    return renderer


def camera_matrices(scene, depsgraph):
    camera = scene.camera.evaluated_get(depsgraph)
    window = camera.calc_matrix_camera(depsgraph, x=WIDTH, y=HEIGHT,
                                       scale_x=scene.render.pixel_aspect_x,
                                       scale_y=scene.render.pixel_aspect_y)
    return camera.matrix_world.inverted(), window


def offscreen_view(renderer, scene, depsgraph, view, window, width=WIDTH, height=HEIGHT):
    """``draw_view`` into a float offscreen; (H, W, 4) top row first."""
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.viewport import draw_view

    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.5, 0.5, 0.5, 1.0))  # grey: what a blank viewport would show
            drawn = draw_view(renderer, scene, depsgraph, view, window, width, height)
        return drawn, np.flipud(read_texture(offscreen.texture_color))
    finally:
        offscreen.free()


def f12_combined(scene, tmp_path):
    from voxgi.voxgi_addon.files.exr import read_exr

    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.filepath = str(tmp_path / "f12.exr")
    bpy.ops.render.render(write_still=True)
    channels = read_exr(str(tmp_path / "f12.exr"))
    prefix = "ViewLayer." if any(k.startswith("ViewLayer.") for k in channels) else ""
    return np.stack([channels[f"{prefix}Combined.{c}"] for c in "RGB"], axis=-1)


@pytest.mark.parametrize("camera_type", ["PERSP", "ORTHO"])
def test_viewport_path_with_the_camera_view_equals_f12(voxgi, tmp_path, camera_type):
    from voxgi.blender.viewport_session import live_gi

    scene = cornell(camera_type)
    scene.voxgi_viewport.resolution_fraction = 1.0
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    plan = live.update(scene, depsgraph)  # what view_update does first: everything
    assert "voxelize" in plan.stages and live.staged is not None and live.error == ""
    renderer = one_shot()
    view, window = camera_matrices(scene, depsgraph)
    drawn, image = offscreen_view(renderer, scene, depsgraph, view, window)
    assert drawn and renderer.traces == 1
    assert live.plans[-1].stages == {"trace"}  # the camera's view: cascades stay where they are

    f12 = f12_combined(scene, tmp_path)
    assert f12[..., 0].sum() > 0 and (f12.sum(-1) > 0).mean() > 0.5
    error = relative_l1(image[..., :3], f12)
    print(f"{camera_type}: viewport vs F12 Combined relative L1 {error:.4f}")
    assert error <= 0.02
    assert np.all(image[..., 3] == 1.0)  # opaque: the grey clear colour never shows

    # Redrawing the same view draws the kept texture without tracing again.
    drawn, again = offscreen_view(renderer, scene, depsgraph, view, window)
    assert drawn and renderer.traces == 1 and np.array_equal(again, image)
    assert renderer.volume.resident_bytes == 0  # Accurate traces the triangles: no atlas

    # A trace setting changes the image: Fast cone-traces the octree the worker laid out.
    scene.voxgi.quality = "FAST"
    drawn, fast = offscreen_view(renderer, scene, depsgraph, view, window)
    assert drawn and renderer.traces == 2 and not np.array_equal(fast, image)
    assert renderer.volume.resident_bytes > 0


@pytest.mark.parametrize("quality", ["FAST", "ACCURATE"])
def test_viewport_keeps_the_last_image_while_newer_work_runs(voxgi, interactive, quality):
    """Interactively, a change only submits a job. Fast cone-traces the worker's voxels: until
    the job is applied, the view draws the last traced image (never blank or grey), then it
    traces the new results. Accurate traces the triangles: the snapshot the change took on the
    main thread is traced at once, without waiting for the worker, and the job's completion
    does not restart that image."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.scene.changes import UpdateRecord, plan_updates

    jobs = interactive
    scene = cornell()
    scene.voxgi.quality = quality
    scene.voxgi_viewport.resolution_fraction = 0.5
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    jobs.synchronous = True
    live.update(scene, depsgraph)
    jobs.synchronous = False
    renderer = one_shot()
    view, window = camera_matrices(scene, depsgraph)
    _, first = offscreen_view(renderer, scene, depsgraph, view, window)
    generation = live.generation

    bpy.data.objects["Test Point Light"].location.x += 0.4
    depsgraph.update()
    moved = UpdateRecord("OBJECT", "Test Point Light", transform=True, object_type="LIGHT")
    job = live.schedule(plan_updates([moved], live.index), scene, depsgraph)
    assert job is not None and job.state == "running"
    _, during = offscreen_view(renderer, scene, depsgraph, view, window)
    if quality == "FAST":
        assert np.array_equal(during, first) and renderer.traces == 1
    else:  # the moved light, traced before the worker is done
        assert renderer.traces == 2 and not np.array_equal(during, first)
    assert job.wait(60) and jobs.drain() and job.state == "done"
    assert live.generation == generation + 1
    _, after = offscreen_view(renderer, scene, depsgraph, view, window)
    assert renderer.traces == 2 and not np.array_equal(after, first)
    if quality == "ACCURATE":
        assert np.array_equal(after, during)  # the same snapshot: kept, not traced again


class Recorder:
    """Collects depsgraph updates as the engine reads them (``records_from_depsgraph``)."""

    def __init__(self, live):
        from voxgi.blender.updates import records_from_depsgraph

        self.live, self.records, self.read = live, [], records_from_depsgraph

    def __call__(self, scene, depsgraph):
        self.records.extend(self.read(depsgraph, self.live.index))

    def take(self):
        records, self.records = self.records, []
        return records


def test_depsgraph_updates_trigger_exactly_the_expected_stages(voxgi):
    """Move an object, pose a bone, move a light, edit a mesh's vertices, change a material
    colour, orbit the view: the planned stages and the work the worker really did."""
    from voxgi.blender.demo_scene import build_demo_scene
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.scene.view_camera import camera_from_view

    scene = bpy.context.scene
    build_demo_scene(scene)
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.1, 3, "32"
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    first = live.update(scene, depsgraph)
    assert "voxelize" in first.stages and live.staged is not None, live.error
    first_voxelized = live.stats.voxelized
    assert len(first_voxelized) == 3  # the box, the sphere, the skinned tube
    recorder = Recorder(live)
    bpy.app.handlers.depsgraph_update_post.append(recorder)
    try:
        def step(edit):
            recorder.take()
            edit()
            bpy.context.view_layer.update()
            generation = live.generation
            plan = live.update(scene, depsgraph, recorder.take())
            ran = live.generation > generation
            return plan, (live.stats if ran else None)

        sphere = bpy.data.objects["Rotating Sphere"]
        plan, stats = step(lambda: setattr(sphere, "location", sphere.location + type(sphere.location)((0.1, 0, 0))))
        assert plan.stages == MOVE and plan.voxelize == set() and stats.voxelized == []
        assert stats.stages == ("transform", "inject", "octree")

        rig = next(o for o in scene.objects if o.type == "ARMATURE")
        bone = rig.pose.bones[-1]
        bone.rotation_mode = "XYZ"
        plan, stats = step(lambda: setattr(bone, "rotation_euler", (0.4, 0.0, 0.0)))
        assert plan.stages == MOVE and stats.voxelized == []

        lamp = next(o for o in scene.objects if o.type == "LIGHT")
        plan, stats = step(lambda: setattr(lamp, "location", lamp.location + type(lamp.location)((0, 0.1, 0))))
        assert plan.stages == LIGHT and stats.voxelized == []
        assert stats.stages == ("inject", "octree")  # the cascades were reused

        mesh = sphere.data
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)

        def edit_vertices():
            mesh.vertices.foreach_set("co", co * 1.1)
            mesh.update()

        plan, stats = step(edit_vertices)
        key = next(o.mesh for o in live.snapshot.objects if o.name == sphere.name)
        assert plan.stages == MOVE | {"voxelize"} and plan.voxelize == {key}
        assert stats.voxelized == [key]  # one mesh, the others' caches kept

        # The full snapshot above re-read the skinned tube (a temporary modifier): its echo
        # schedules nothing.
        echo, _ = step(lambda: None)
        assert echo.empty, echo

        material = sphere.material_slots[0].material
        bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
        plan, stats = step(lambda: bsdf.inputs["Base Color"].default_value.__setitem__(0, 0.05))
        assert plan.stages == MOVE | {"albedo"} and plan.albedo == {key}
        assert stats.voxelized == [key]  # the albedo refresh re-voxelizes that mesh
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(recorder)

    # Orbit the view a little around the camera's target: trace only.
    view = np.array(scene.camera.matrix_world.inverted())
    window = np.array(scene.camera.calc_matrix_camera(depsgraph, x=64, y=48))
    live.view_changed(camera_from_view(view, window, 64, 48))
    turn = np.eye(4)
    c, s = np.cos(0.02), np.sin(0.02)
    turn[:2, :2] = ((c, -s), (s, c))
    generation = live.generation
    plan = live.view_changed(camera_from_view(view @ turn, window, 64, 48))
    assert plan.stages == {"trace"} and live.generation == generation
    # Far away, the cascades follow the view: rebuilt, never re-voxelized.
    away = np.eye(4)
    away[:3, 3] = (-8.0, 0.0, 0.0)
    plan = live.view_changed(camera_from_view(view @ away, window, 64, 48))
    assert plan.stages == {"transform", "inject", "octree", "trace"}
    assert live.generation == generation + 1 and live.stats.voxelized == []

    counts = live.planned.snapshot()
    assert counts["voxelize"] == 2 and counts["albedo"] == 1  # first update + the vertex edit
    assert live.planned.voxelized == [key] and live.planned.recoloured == [key]


class Dispatches:
    """Counts ``gpu.compute.dispatch`` calls: every kernel of a trace goes through it."""

    def __init__(self, monkeypatch):
        self.count = self.groups = 0  # calls; work groups (x × y × z) dispatched
        original = gpu.compute.dispatch

        def counted(shader, x, y, z, *args, **kwargs):
            self.count += 1
            self.groups += x * y * z
            return original(shader, x, y, z, *args, **kwargs)

        monkeypatch.setattr(gpu.compute, "dispatch", counted)

    def take(self) -> int:
        count, self.count = self.count, 0
        return count

    def take_groups(self) -> int:
        groups, self.groups = self.groups, 0
        return groups


def turned(view, degrees):
    """The view matrix orbited by ``degrees`` about the world's z axis."""
    from mathutils import Matrix

    return view @ Matrix.Rotation(np.radians(degrees), 4, "Z")


def test_an_unchanged_redraw_traces_nothing_and_any_change_traces_again(voxgi, monkeypatch):
    """The last image is keyed by what it depends on: a redraw with nothing changed
    dispatches no compute work and draws the same pixels; a view, projection, region size,
    scene or tracer setting change traces again."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.scene.changes import UpdateRecord

    scene = cornell()
    scene.voxgi_viewport.resolution_fraction = 0.5
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    renderer = one_shot()
    view, window = camera_matrices(scene, depsgraph)
    dispatches = Dispatches(monkeypatch)

    drawn, first = offscreen_view(renderer, scene, depsgraph, view, window)
    assert drawn and renderer.traces == 1 and dispatches.take() > 0
    assert renderer.shown == "Converged"
    for _ in range(2):
        drawn, again = offscreen_view(renderer, scene, depsgraph, view, window)
        assert drawn and dispatches.take() == 0 and renderer.traces == 1
        assert np.array_equal(again, first) and renderer.shown == "Cached"
    assert "Sample 1/1 | Converged in" in renderer.status and live.view_shown == "Cached"

    # the view orbits by 2°: traced again, a different image
    view2 = turned(view, 2.0)
    drawn, orbit = offscreen_view(renderer, scene, depsgraph, view2, window)
    assert drawn and dispatches.take() > 0 and renderer.traces == 2
    assert not np.array_equal(orbit, first)
    # another projection (zoom) and another region size trace too
    zoom = window.copy()
    zoom[0][0] *= 1.1
    offscreen_view(renderer, scene, depsgraph, view2, zoom)
    assert dispatches.take() > 0 and renderer.traces == 3
    offscreen_view(renderer, scene, depsgraph, view2, zoom, WIDTH - 8, HEIGHT)
    assert dispatches.take() > 0 and renderer.traces == 4
    offscreen_view(renderer, scene, depsgraph, view2, zoom, WIDTH - 8, HEIGHT)
    assert dispatches.take() == 0 and renderer.traces == 4

    # a tracer setting that used to be missing from the key (AO distance) traces again
    scene.voxgi.ao_distance *= 0.5
    offscreen_view(renderer, scene, depsgraph, view2, zoom, WIDTH - 8, HEIGHT)
    assert dispatches.take() > 0 and renderer.traces == 5

    # an object moves: the session applies new results, the next draw traces them
    box = bpy.data.objects["Test Box"]
    box.location.x += 0.2
    depsgraph.update()
    generation = live.generation
    plan = live.update(scene, depsgraph, [UpdateRecord("OBJECT", box.name, transform=True,
                                                       object_type="MESH")])
    assert "transform" in plan.stages and live.generation == generation + 1, live.error
    _, moved = offscreen_view(renderer, scene, depsgraph, view, window)
    assert dispatches.take() > 0 and renderer.traces == 6
    assert not np.array_equal(moved, first)
    _, still = offscreen_view(renderer, scene, depsgraph, view, window)
    assert dispatches.take() == 0 and np.array_equal(still, moved)


def engine_view(engine, scene, depsgraph, view, window, width=WIDTH, height=HEIGHT,
                perspective="PERSP"):
    """``view_draw`` itself into a float offscreen; (H, W, 4) top row first. perspective :
    the region's ``view_perspective`` ("CAMERA": the camera view)."""
    import types

    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.viewport import view_draw

    context = types.SimpleNamespace(
        region=types.SimpleNamespace(width=width, height=height),
        region_data=types.SimpleNamespace(view_matrix=view, window_matrix=window,
                                          view_perspective=perspective))
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.5, 0.5, 0.5, 1.0))
            view_draw(engine, context, depsgraph)
        return np.flipud(read_texture(offscreen.texture_color))
    finally:
        offscreen.free()


def about_half(size) -> bool:
    """A coarse image of about half the view's width and height, its sides of the tiles'
    kind (whole work groups of the gather grid, no power of two: ``progressive.tile_side``)."""
    from voxgi.render.gpu_shaders import LOCAL_SIZE

    return abs(size[0] - WIDTH // 2) <= LOCAL_SIZE and abs(size[1] - HEIGHT // 2) <= LOCAL_SIZE \
        and all(side % LOCAL_SIZE == 0 and side & (side - 1) for side in size)


def test_a_changed_view_shows_a_coarse_image_first_then_the_full_one(voxgi, monkeypatch, tmp_path):
    """With Coarse First Image (the default) the first ``view_draw`` after a change traces the
    whole view at low resolution (here about a quarter of the pixels: one slice may hold the
    whole image), draws it (never a blank view) and asks for a redraw; the next traces the full
    image; the one after only draws it. The header's status line (``update_stats``) and the
    sidebar say which."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.ui.viewport_panel import view_state_line

    scene = cornell()
    scene.voxgi_viewport.coarse_first = True
    scene.voxgi_viewport.resolution_fraction = 1.0
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    renderer = engine.voxgi_viewport = one_shot()
    dispatches = Dispatches(monkeypatch)

    def filled(image):  # the share of pixels that are not the grey clear colour
        return float((np.abs(image[..., :3] - 0.5).sum(-1) > 1e-6).mean())

    coarse = engine_view(engine, scene, depsgraph, view, window)
    assert about_half(renderer.progressive.last.size), renderer.progressive.last.size
    assert dispatches.take() > 0 and engine.redraws == 1 and filled(coarse) > 0.99
    assert engine.stats[-1].startswith("VoxGI | Sample 0/1 | ")
    assert engine.stats[-1].endswith("| Coarse image | Accurate")
    assert view_state_line(live) == "Refining: a coarse first image"

    full = engine_view(engine, scene, depsgraph, view, window)
    assert renderer.progressive.last.size == (WIDTH, HEIGHT)
    assert dispatches.take() > 0 and engine.redraws == 1 and renderer.traces == 2
    assert engine.stats[-1].startswith("VoxGI | Sample 1/1 | Converged in ")
    assert engine.stats[-1].endswith("| Accurate")
    # the coarse image is the full one at half the resolution: close, not equal
    assert not np.array_equal(coarse, full) and relative_l1(coarse[..., :3], full[..., :3]) < 0.25
    # and the full image after it is F12's, as without the coarse one
    # (view_draw once traced with its blending on: its G-buffer triangles blended, 0.034 off)
    assert relative_l1(full[..., :3], f12_combined(scene, tmp_path)) <= 0.02
    dispatches.take()  # F12's own

    cached = engine_view(engine, scene, depsgraph, view, window)
    assert dispatches.take() == 0 and engine.redraws == 1 and np.array_equal(cached, full)
    assert engine.stats[-1].startswith("VoxGI | Sample 1/1 | Converged in ")
    assert view_state_line(live) == "Converged: 1 of 1 samples"

    # a camera move: a coarse, non-empty image on the very next call, then the full one
    moved = engine_view(engine, scene, depsgraph, turned(view, 2.0), window)
    assert about_half(renderer.progressive.last.size) and engine.redraws == 2
    assert dispatches.take() > 0 and renderer.shown == "Coarse" and filled(moved) > 0.99
    engine_view(engine, scene, depsgraph, turned(view, 2.0), window)
    assert renderer.progressive.last.size == (WIDTH, HEIGHT) and renderer.shown == "Converged"
    assert engine.redraws == 2


def test_the_coarse_first_image_dispatches_about_a_quarter_of_the_work(voxgi, monkeypatch):
    """When one slice may hold the whole image, the coarse image is half its width and height,
    traced at the full image's GI stride (GI Resolution Auto would pick a finer stride for the
    smaller image and gather as many points as the full one)."""
    from voxgi.blender.viewport_session import live_gi

    scene = cornell()
    scene.voxgi_viewport.coarse_first = True
    scene.voxgi_viewport.resolution_fraction = 1.0
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    engine.voxgi_viewport = one_shot()
    dispatches = Dispatches(monkeypatch)
    size = (4 * WIDTH, 4 * HEIGHT)  # 256 × 192: GI Resolution Auto traces every 2nd pixel
    engine_view(engine, scene, depsgraph, view, window, *size)
    coarse = dispatches.take_groups()
    engine_view(engine, scene, depsgraph, view, window, *size)
    full = dispatches.take_groups()
    assert engine.voxgi_viewport.shown == "Converged" and engine.redraws == 1
    print(f"work groups: coarse {coarse}, full {full} ({coarse / full:.2f})")
    assert 0.15 * full < coarse < 0.35 * full


def test_the_texture_draw_is_built_before_the_first_image_without_changing_a_pixel(voxgi):
    """Before a view has an image, a draw with time to spare draws a transparent texel with
    the display's blending (llvmpipe builds the texture draw's code there, not in the draw
    that shows the first image beside its last stages): no pixel of the view changes, and it
    happens once, and not in a draw that already did most of its work."""
    from voxgi.render.viewport import WARM_DISPLAY_WORK, ViewportRenderer

    gpu_ready()
    w, h = 400, 300  # (the texel's corner quad covers pixels there, as in a 3D view)
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    background = (0.2, 0.4, 0.6, 1.0)

    def drawn(renderer):
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=background)
            gpu.state.blend_set("ALPHA_PREMULT")
            try:
                shown = renderer.draw()
            finally:
                gpu.state.blend_set("NONE")
            pixels = np.array(fb.read_color(0, 0, w, h, 4, 0, "FLOAT").to_list(), np.float32)
        return shown, pixels.reshape(h, w, 4)

    busy = ViewportRenderer()
    busy.timings = {"view_draw work": 2.0 * WARM_DISPLAY_WORK * busy.progressive.budget}
    shown, pixels = drawn(busy)
    assert not shown and not busy.display_warm  # a draw that worked: left for a later one
    renderer = ViewportRenderer()
    shown, pixels = drawn(renderer)
    assert not shown and renderer.display_warm
    np.testing.assert_allclose(pixels, np.broadcast_to(background, pixels.shape), atol=1e-6)
    offscreen.free()

"""Entering Rendered mode without a freeze (render/viewport_prepare.py; docs/gi_pipeline.md
"Entering Rendered mode"): counted, not timed.

``view_update`` / ``view_draw`` are driven headless with the stand-in engine, as the other
viewport tests do, from cold caches (no shader compiled, no GPU scene): from entering Rendered
mode to the converged image no draw compiles more than one shader (``gpu.shader.create_from_info``
calls, counted beside ``gpu_shaders.counters``) or sends more than one scene part
(``gpu_shaders.counters``: the GPU scene's parts, the BVH's three textures one by one, the
vertex batch a chunk at a time); the quick image shows before the first GI image; the kernels
compiled before the first GI image are exactly the minimal frame's (``FIRST_IMAGE_KERNELS``);
no slice draws a G-buffer before it (the first coarse image's is the quick image's, each chunk
drawn into it once); the first GI image arrives; and the converged image is the one the view
converged to before the change (every step of it in one draw: a whole slice per draw, no
budget), traced in the same test.
An object move and an orbit then keep to the same counts.
"""
from __future__ import annotations

import types

import bpy
import gpu
import numpy as np
from stand_in_engine import StandInEngine
from test_viewport import HEIGHT, WIDTH, camera_matrices, gpu_ready, turned

SAMPLES = 3
# the kernels compiled from entering Rendered mode to the first GI image on the demo scene
# (one lamp, a world): the G-buffer raster, the quick image's shade and the first coarse
# image's minimal frame — the diffuse gather unfiltered and upsampled, the surface terms, the
# lamp's and the world's direct light composed (one variant of the direct light for both), and
# the accumulation's three — and nothing of the glossy gathers, the lamps' glossy light or the
# filter (docs/gi_pipeline.md "Entering Rendered mode", "One direct-light variant per scene")
FIRST_IMAGE_KERNELS = sorted(["gbuffer raster", "quick shade", "bvh_gather", "upsample",
                              "aa_surface", "bvh_direct", "aa_light",
                              "pass_sample", "accumulate", "estimate"])


class Compiles:
    """Counts ``gpu.shader.create_from_info`` calls: every shader the add-on makes."""

    def __init__(self, monkeypatch):
        self.count = 0
        original = gpu.shader.create_from_info

        def counted(info):
            self.count += 1
            return original(info)

        monkeypatch.setattr(gpu.shader, "create_from_info", counted)

    def take(self) -> int:
        count, self.count = self.count, 0
        return count


def demo_scene():
    """The demo scene (the viewport benchmark's box: a textured floor, a skinned tube, a
    sphere, a point lamp, a world), Accurate with the radiance cache's bounces."""
    from voxgi.blender.demo_scene import build_demo_scene

    scene = bpy.context.scene
    build_demo_scene(scene)
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.voxgi.quality = "ACCURATE"
    scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 3
    # small voxels for the session's update jobs (Accurate traces the triangles)
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.2, 2, "32"
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = SAMPLES
    return scene


def cold_caches():
    """Forget every compiled shader, the GPU scene and the prepared one: as a fresh session."""
    from voxgi.render import gpu_scene, release_gpu_resources

    release_gpu_resources()
    gpu_scene.release()


def context(view, window):
    return types.SimpleNamespace(
        region=types.SimpleNamespace(width=WIDTH, height=HEIGHT),
        region_data=types.SimpleNamespace(view_matrix=view, window_matrix=window))


def draw(engine, depsgraph, view, window):
    """``view_draw`` into a float offscreen: (H, W, 4), top row first."""
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.viewport import view_draw

    offscreen = gpu.types.GPUOffScreen(WIDTH, HEIGHT, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.5, 0.5, 0.5, 1.0))
            view_draw(engine, context(view, window), depsgraph)
        return np.flipud(read_texture(offscreen.texture_color))
    finally:
        offscreen.free()


def renderer_for(engine, whole: bool):
    """The engine's renderer with quarter-image slices (the sizes do not depend on the
    machine); whole: no budget — every preparation step and a whole slice in one draw, the
    view as it converged before the preparation was spread over draws."""
    from voxgi.render.viewport import ViewportRenderer

    renderer = engine.voxgi_viewport = ViewportRenderer()
    renderer.progressive.fixed_pixels = WIDTH * HEIGHT // 4
    if whole:
        renderer.progressive.stage_budget = None
    return renderer


def draw_to_the_end(engine, depsgraph, view, window, compiles, limit=3000, drawn=None):
    """view_draw until the view has converged on the completed radiance cache and asks for no
    more draws: [(image, shader compiles, scene parts sent, what it showed, …, the entries
    ``drawn`` got in the draw)]."""
    from voxgi.render.gpu_shaders import counters

    renderer = engine.voxgi_viewport
    draws = []
    for _ in range(limit):
        redraws = engine.redraws
        mark = counters.mark()
        image = draw(engine, depsgraph, view, window)
        compiled, sent = counters.since(mark)
        got = [] if drawn is None else drawn[:]
        if drawn is not None:
            drawn.clear()
        last = renderer.progressive.last
        draws.append((image, compiles.take(), len(compiled), len(sent), renderer.shown,
                      compiled, sent, renderer.traces, dict(renderer.timings), got,
                      None if last is None else (last.kind, tuple(last.size))))
        if engine.redraws == redraws and renderer.progressive.converged \
                and renderer.cache.generation > 0:
            return draws
    raise AssertionError(f"the view did not converge in {limit} draws: {renderer.status}")


def assert_bounded(draws, what):
    for index, (_, compiles, counted, sent, _, names, parts, *_) in enumerate(draws):
        assert compiles == counted, f"{what} draw {index}: a compile bypassed create_shader"
        assert compiles <= 1, f"{what} draw {index} compiled {compiles} shaders: {names}"
        assert sent <= 1, f"{what} draw {index} sent {sent} scene parts: {parts}"


def test_no_draw_compiles_or_uploads_more_than_one_thing_and_the_image_is_the_same(
        voxgi, monkeypatch):
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import viewport_prepare
    from voxgi.render.viewport import view_update
    from voxgi.voxgi_addon.scene.changes import UpdateRecord

    scene = demo_scene()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    compiles = Compiles(monkeypatch)

    # before: every step in one draw, the triangles in one vertex batch, converged
    monkeypatch.setattr(viewport_prepare, "CHUNK_TRIANGLES", 1 << 30)
    cold_caches()
    engine = StandInEngine()
    view_update(engine, context(view, window), depsgraph)
    renderer_for(engine, whole=True)
    before = draw_to_the_end(engine, depsgraph, view, window, compiles)
    assert max(d[1] for d in before) > 1  # (the first draw compiles all the kernels)
    reference = before[-1][0]

    # entering Rendered mode from cold caches, spread over draws; the vertex batch in several
    # chunks and the scene's parts a texture a step on this small scene, as on a large one
    # (its small tables go in one step otherwise: test_small_scene_parts_go_together)
    from voxgi.render import gpu_scene

    monkeypatch.setattr(viewport_prepare, "CHUNK_TRIANGLES", 512)
    monkeypatch.setattr(gpu_scene, "PART_BYTES", 0)
    cold_caches()
    live_gi(scene.name_full).rescan = "entering Rendered mode again"
    engine = StandInEngine()
    compiles.take()
    # the meshes read a slice a draw, as on a large scene (LiveGI.read_on)
    from voxgi.render import viewport

    monkeypatch.setattr(viewport, "READ_SLICE", 1e-9)
    view_update(engine, context(view, window), depsgraph)  # a mesh read
    assert live_gi(scene.name_full).reading is not None  # the snapshot waits for the others
    entering = compiles.take()
    assert entering == 0, f"view_update compiled {entering} shaders"
    renderer_for(engine, whole=False)
    # the G-buffers drawn: the quick image's chunks (viewport_prepare) and the slices' own
    from voxgi.render import gpu_preview

    drawn = []
    for module, name in ((viewport_prepare, "rasterize"), (gpu_preview, "rasterize_stages")):
        def counted(*args, _original=getattr(module, name), _name=name, **kwargs):
            drawn.append((_name, args[3:5]))  # (which, (width, height))
            return _original(*args, **kwargs)
        monkeypatch.setattr(module, name, counted)
    draws = draw_to_the_end(engine, depsgraph, view, window, compiles, drawn=drawn)
    assert_bounded(draws, "entering")
    shown = [d[4] for d in draws]
    first_quick = shown.index("Quick")
    first_gi = next(i for i, d in enumerate(draws) if d[7])  # its first slice done
    print(f"{len(draws)} draws: quick image at draw {first_quick}, first GI image at draw "
          f"{first_gi}; {sum(d[1] for d in draws)} compiles, {sum(d[3] for d in draws)} parts")
    assert first_quick < first_gi  # the quick image shows while the kernels come in
    # the kernels compiled before the first GI image: exactly the minimal frame's
    before_gi = sorted(name for d in draws[:first_gi + 1] for name in d[5])
    assert before_gi == FIRST_IMAGE_KERNELS, before_gi
    later = [name for d in draws[first_gi + 1:] for name in d[5]]
    assert "denoise" in later and "glossy_direct" in later, later  # (before the tiles use them)
    # the first coarse image's G-buffer is the quick image's: from entering to the first GI
    # image no slice draws one, and the quick image's chunks are drawn into it once each (by
    # the batch's fill as each is sent, or after), at the coarse image's size
    kind, coarse_size = draws[first_gi][10]  # the first slice's
    assert kind == "coarse", draws[first_gi][10]
    entering_draws = [g for d in draws[:first_gi + 1] for g in d[9]]
    assert not [g for g in entering_draws if g[0] == "rasterize_stages"], entering_draws
    into = [g for g in entering_draws if g[0] == "rasterize" and g[1] == tuple(coarse_size)]
    batch = engine.voxgi_viewport.prepare.batch
    assert len(into) == len(batch.batches), (into, len(batch.batches), coarse_size)
    assert sum(d[1] for d in draws) >= 15  # every kernel compiled, one per draw
    assert sum(d[3] for d in draws) >= 6   # the scene's parts and the vertex batch's chunks
    # the raster shader's first draw (llvmpipe builds its draw variant there) is a step of its
    # own: not in its compile's draw, before the batch's first chunk, which then goes alone
    warm = [i for i, d in enumerate(draws) if "raster first draw" in d[8]]
    compiled_raster = next(i for i, d in enumerate(draws) if "gbuffer raster" in d[5])
    first_chunk = next(i for i, d in enumerate(draws)
                       if any(p.startswith("vertex batch") for p in d[6]))
    assert len(warm) == 1 and compiled_raster < warm[0] < first_chunk, \
        (warm, compiled_raster, first_chunk)
    # the image the view converged to before, within float rounding
    np.testing.assert_allclose(draws[-1][0], reference, atol=1e-5)

    # an object moves: a new snapshot, its changed parts a draw each, nothing compiled
    sphere = bpy.data.objects["Rotating Sphere"]
    sphere.location.x += 0.3
    depsgraph.update()
    live_gi(scene.name_full).update(scene, depsgraph, [UpdateRecord(
        "OBJECT", sphere.name, transform=True, object_type="MESH")])
    moved = draw_to_the_end(engine, depsgraph, view, window, compiles)
    assert_bounded(moved, "object move")
    assert sum(d[1] for d in moved) == 0
    assert any("bvh" in part for d in moved for part in d[6])
    assert not np.allclose(moved[-1][0], draws[-1][0], atol=1e-3)

    # an orbit: a new view every draw, nothing compiled or sent
    for step in range(1, 6):
        mark = compiles.take()
        draw(engine, depsgraph, turned(view, 2.0 * step), window)
        assert compiles.take() == 0 and mark == 0


def test_a_radiance_cache_completed_in_a_draw_asks_for_the_next_draw(voxgi, monkeypatch):
    """A build of the radiance cache can complete inside a slice's cache stage, in the very draw
    whose slice converges the image. The image key holds the cache's generation, so that draw
    must ask for the next one: without it the view stayed on the one-bounce image it had
    converged on until something else redrew it. A draw that changed nothing asks for none."""
    from voxgi.render.viewport import ViewportRenderer, view_update

    scene = demo_scene()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    view_update(engine, context(view, window), depsgraph)
    renderer_for(engine, whole=True)

    def completes(self, live, scene, view, window):  # traced nothing more, but the build ended
        self.cache.generation += 1
        return ""

    monkeypatch.setattr(ViewportRenderer, "refine", completes)
    before = engine.redraws
    draw(engine, depsgraph, view, window)
    assert engine.redraws == before + 1

    monkeypatch.setattr(ViewportRenderer, "refine", lambda self, live, scene, view, window: "")
    before = engine.redraws
    draw(engine, depsgraph, view, window)
    assert engine.redraws == before


def test_kernels_warmed_with_the_file_open_leave_the_draws_the_scenes_own(voxgi, monkeypatch):
    """render/kernel_warmup.py: while a VoxGI file is open, the add-on's timer compiles the
    views' scene-independent kernels, one a tick, and nothing for a scene another engine
    renders. Entering Rendered mode after it compiles before the first GI image only the
    G-buffer raster and the scene's BVH variants, one a draw, prepares the view in fewer draws
    than from cold caches, and converges to the same image."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_scene, kernel_warmup, viewport_prepare
    from voxgi.render.viewport import view_update

    scene = demo_scene()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    compiles = Compiles(monkeypatch)
    monkeypatch.setattr(viewport_prepare, "CHUNK_TRIANGLES", 512)

    def entering(warm: bool):
        cold_caches()
        compiles.take()
        if warm:
            scene.render.engine = "CYCLES"
            assert kernel_warmup.tick(scene) == kernel_warmup.IDLE_SECONDS
            assert compiles.take() == 0  # not a VoxGI file: nothing compiled
            scene.render.engine = "VOXGI"
            ticks = []
            while True:
                wait = kernel_warmup.tick(scene)
                ticks.append(compiles.take())
                if wait == kernel_warmup.IDLE_SECONDS:
                    break
            assert ticks[-1] == 0 and set(ticks[:-1]) == {1}, ticks  # one compile a tick
            assert len(ticks) > 8
            assert kernel_warmup.done(scene.voxgi)  # the next ticks touch no GPU
        live_gi(scene.name_full).rescan = "entering Rendered mode again"
        engine = StandInEngine()
        view_update(engine, context(view, window), depsgraph)
        renderer_for(engine, whole=False)
        draws = draw_to_the_end(engine, depsgraph, view, window, compiles)
        assert_bounded(draws, "entering")
        first_gi = next(i for i, d in enumerate(draws) if d[7])
        # the draws that prepared the view before its first GI slice, not counting those
        # that only waited for the preparing thread (their number, and the coarse image's
        # stages after, follow the machine's speed: the draws' time budget)
        preparing = [d for d in draws[:first_gi] if d[4] in ("Preparing", "Quick")
                     and set(d[8]) != {"view_draw work"}]
        return draws, first_gi, len(preparing)

    cold, cold_first, cold_preparing = entering(False)
    warmed, warm_first, warm_preparing = entering(True)
    before_gi = sorted(name for d in warmed[:warm_first + 1] for name in d[5])
    generic = {name for name, _, _ in kernel_warmup.generic_steps(scene.voxgi)[1]}
    assert before_gi == sorted(k for k in FIRST_IMAGE_KERNELS if k not in generic), before_gi
    assert before_gi == ["bvh_direct", "bvh_gather", "gbuffer raster"]
    assert warm_preparing < cold_preparing, (warm_preparing, cold_preparing)
    print(f"the view prepared in {warm_preparing} draws with the kernels warmed, "
          f"{cold_preparing} from cold caches; first GI image at draw {warm_first} / {cold_first}")
    np.testing.assert_allclose(warmed[-1][0], cold[-1][0], atol=1e-5)
    assert gpu_scene.PART_BYTES > 0


def test_a_playing_rig_shows_one_frame_after_another_the_newest_next(voxgi, monkeypatch):
    """Frames of a playing rig come faster than a frame's image (its GPU scene, then its
    coarse slice, a step a draw): the view finishes the frame it is preparing and shows it,
    then goes on with the newest, dropping the ones between (``viewport_prepare.hold_source``);
    before, every new frame superseded the one being prepared and no frame's image was drawn
    while the rig played."""
    import rig_scenes
    from test_posed_update import Recorder

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_scene, viewport_prepare
    from voxgi.render.viewport import view_update

    scene = bpy.context.scene
    built = rig_scenes.build_gltf_rig_room(scene, 0.5)
    rig_scenes.keyframe_walk(built["rig"], frames=5, start=1)
    scene.frame_set(1)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.voxgi.quality = "ACCURATE"
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.2, 2, "32"
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = SAMPLES
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    # a frame's GPU scene in several steps, as a large scene's
    monkeypatch.setattr(viewport_prepare, "CHUNK_TRIANGLES", 512)
    monkeypatch.setattr(gpu_scene, "PART_BYTES", 0)
    engine = StandInEngine()
    view_update(engine, context(view, window), depsgraph)
    renderer = renderer_for(engine, whole=False)
    for _ in range(600):  # Rendered mode entered: to the first GI image
        draw(engine, depsgraph, view, window)
        if renderer.traces:
            break
    assert renderer.traces
    live = live_gi(scene.name_full)
    recorder = Recorder(live)
    bpy.app.handlers.depsgraph_update_post.append(recorder)
    bpy.app.handlers.frame_change_post.append(recorder)
    versions, shown = {}, []
    try:
        for frame in (2, 3, 4):  # a draw between frames: no frame's image is ready in it
            scene.frame_set(frame)
            live.update(scene, depsgraph, recorder.take())
            versions[frame] = ("snapshot", live.snapshots)
            draw(engine, depsgraph, view, window)
            shown.append(renderer.shown_version)
        for _ in range(600):
            draw(engine, depsgraph, view, window)
            shown.append(renderer.shown_version)
            if renderer.shown_version == versions[4]:
                break
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(recorder)
        bpy.app.handlers.frame_change_post.remove(recorder)
    order = [v for i, v in enumerate(shown) if v in versions.values() and v not in shown[:i]]
    assert order == [versions[2], versions[4]], (order, versions)  # frame 3 dropped


def test_a_view_waiting_for_its_scene_asks_for_a_redraw_only_once_it_moved_on(interactive,
                                                                              monkeypatch):
    """A draw with nothing to do but wait for the preparing thread (here its BVH build, held)
    asks for no redraw at once: each redraw would draw the last image again, taking the cores
    from that build. The view's timer (``viewport_prepare.wake_tick``, run here as Blender's
    event loop would) asks for it once the build is in, and the view then converges."""
    import threading

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_bvh, viewport_prepare
    from voxgi.render.viewport import view_update

    scene = demo_scene()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    compiles = Compiles(monkeypatch)
    release, entered = threading.Event(), threading.Event()
    pack = gpu_bvh.GPUBVH.pack

    def held(self, tris):
        entered.set()
        assert release.wait(60.0)
        return pack(self, tris)

    monkeypatch.setattr(gpu_bvh.GPUBVH, "pack", held)
    # a loaded machine may take longer than the wait's deadline between two lines here
    monkeypatch.setattr(viewport_prepare, "WAKE_MOST", 60.0)
    cold_caches()
    live_gi(scene.name_full).rescan = "entering Rendered mode again"
    engine = StandInEngine()
    view_update(engine, context(view, window), depsgraph)
    renderer = renderer_for(engine, whole=False)
    try:
        waited = None
        for index in range(200):  # the steps it can take while the BVH builds, then waiting
            interactive.drain()
            before = engine.redraws
            draw(engine, depsgraph, view, window)
            if renderer.shown == "Preparing" and not renderer.prepare.timings:
                assert engine.redraws == before  # waiting: no redraw asked
                assert entered.wait(60.0)  # the thread is at the held build: nothing moves on
                if viewport_prepare.wake_tick() == viewport_prepare.WAKE_POLL:
                    waited = index  # it waits for the build itself: the timer polls on
                    break
                # it had waited for an earlier hand-over (the arrays, the tables), and the
                # thread has moved on since: the timer asked for the redraw
                assert engine.redraws == before + 1
                continue
            if renderer.shown in ("Preparing", "Quick"):  # a step: the next draw at once
                assert engine.redraws == before + 1, renderer.timings
        assert waited is not None, "the view never waited for its BVH"
        assert viewport_prepare.wake_tick() == viewport_prepare.WAKE_POLL
        assert engine.redraws == before  # still building: the timer polls on, no redraw
    finally:
        release.set()
    for _ in range(600):
        if viewport_prepare.wake_tick() is None:
            break
        threading.Event().wait(viewport_prepare.WAKE_POLL)
    assert engine.redraws == before + 1  # the build is in: one redraw asked
    for _ in range(200):  # and the view goes on to its first GI image
        draw(engine, depsgraph, view, window)
        if renderer.traces:
            break
    assert renderer.traces and renderer.shown == "Coarse", renderer.status
    assert compiles.take() > 0

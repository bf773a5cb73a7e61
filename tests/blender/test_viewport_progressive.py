"""Issue 19's acceptance: the Rendered view refines progressively in bounded slices.

``view_draw`` (with the stand-in engine) is drawn many times into an offscreen buffer: each
call dispatches at most one slice (work groups counted, never wall-clock), the image after
every sample has landed is F12's within its own noise, and a camera move, a scene change or a
setting change restarts the accumulation and draws a non-empty image on the very next call.
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest
from stand_in_engine import StandInEngine
from test_viewport import (
    HEIGHT,
    WIDTH,
    Dispatches,
    bake_queued,
    camera_matrices,
    cornell,
    engine_view,
    f12_combined,
    gpu_ready,
    live_view,
    relative_l1,
    turned,
)

SAMPLES = 16


def filled(image) -> float:
    """The share of pixels that are not the grey clear colour (a blank view is all grey)."""
    return float((np.abs(image[..., :3] - 0.5).sum(-1) > 1e-6).mean())


def progressive_scene(light="POINT"):
    scene = cornell(light=light)
    scene.cycles.filter_width = 1.5  # Cycles' default: the samples' offsets anti-alias
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.coarse_first = True
    scene.voxgi_viewport.samples = SAMPLES
    return scene


def quarter_slices(engine):
    """The engine's renderer with every slice a quarter of the image (the slice size is
    otherwise measured from dispatch times: a test must not depend on the machine's speed)."""
    from voxgi.render.viewport import ViewportRenderer

    renderer = engine.voxgi_viewport = ViewportRenderer()
    renderer.progressive.fixed_pixels = WIDTH * HEIGHT // 4
    renderer.progressive.stage_budget = None  # a whole slice per draw (staged: its own test)
    return renderer


def quarter_view(light="POINT"):
    """(scene, depsgraph, view, window, engine, renderer): the progressive box's session
    updated and a stand-in engine whose slices are quarters (``quarter_slices``)."""
    from voxgi.blender.viewport_session import live_gi

    scene = progressive_scene(light)
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    return scene, depsgraph, view, window, engine, quarter_slices(engine)


def one_sample_groups(scene, live, dispatches) -> int:
    """Work groups of one sample of the whole image traced in one call (what a slice is a
    part of)."""
    from voxgi.render.progressive import base_options, tracer
    from voxgi.voxgi_addon.preview.progressive import sample_settings
    from voxgi.voxgi_addon.scene.view_camera import camera_from_view

    view, window = camera_matrices(scene, bpy.context.evaluated_depsgraph_get())
    options = base_options(scene.voxgi, WIDTH, HEIGHT)
    gather, lights = sample_settings(options["gather_settings"], options["light_samples"],
                                     SAMPLES, 0)
    camera = camera_from_view(np.array(view), np.array(window), WIDTH, HEIGHT)
    dispatches.take(), dispatches.take_groups()
    tracer(live, None, scene.voxgi)(camera, WIDTH, HEIGHT, {
        **options, "gather_settings": gather, "light_samples": lights})
    dispatches.take()
    return dispatches.take_groups()


def draw_until_samples(engine, scene, depsgraph, view, window, samples: int, limit: int = 200):
    """view_draw until the view has ``samples`` samples whole (their last tile in): the last
    image drawn."""
    image = None
    for _ in range(limit):
        image = engine_view(engine, scene, depsgraph, view, window)
        if engine.voxgi_viewport.progressive.samples_done >= samples:
            break
    assert engine.voxgi_viewport.progressive.samples_done == samples
    return image


def draw_until_converged(engine, scene, depsgraph, view, window, dispatches, limit):
    """view_draw until the engine stops asking for redraws: [(image, groups, calls)]. Only
    the draws before the view's first image — those that make it ready
    (render/viewport_prepare.py: the scene, the vertex batch, the kernels, a step a draw when
    staged) and the first slice's stages — may leave it blank."""
    draws = []
    for _ in range(2000):
        redraws = engine.redraws
        image = engine_view(engine, scene, depsgraph, view, window)
        draws.append((image, dispatches.take_groups(), dispatches.take()))
        assert filled(image) > 0.99 or engine.voxgi_viewport.texture is None, \
            f"draw {len(draws)} left the view blank"
        assert draws[-1][1] <= limit, f"draw {len(draws)} dispatched {draws[-1][1]} groups"
        if engine.redraws == redraws:
            return draws
    raise AssertionError("the view never converged")


def test_each_view_draw_traces_one_slice_and_the_samples_converge_to_f12(voxgi, monkeypatch,
                                                                         tmp_path):
    from voxgi.blender.viewport_session import live_gi
    from voxgi.ui.viewport_panel import view_state_line

    scene = progressive_scene()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    dispatches = Dispatches(monkeypatch)
    full = one_sample_groups(scene, live, dispatches)
    engine = StandInEngine()
    renderer = quarter_slices(engine)

    # a slice is a quarter of one sample's pixels: a quarter of its work groups, plus the
    # small dispatches (light tables) every tracer call makes, plus one per-pixel pass over
    # the image that makes the shown image from the sums on the GPU (gpu_accumulation: the
    # converged image's pixel filter touches every pixel)
    limit = int(0.3 * full) + -(-WIDTH // 8) * -(-HEIGHT // 8)
    draws = draw_until_converged(engine, scene, depsgraph, view, window, dispatches, limit)
    slices = len(draws)
    progressive = renderer.progressive
    print(f"one sample {full} groups; {slices} slices, at most "
          f"{max(d[1] for d in draws)} groups and {max(d[2] for d in draws)} dispatches each")
    assert progressive.converged and progressive.samples_done == SAMPLES
    # a coarse image, then SAMPLES samples of 4 to 12 tiles (the grid moves each sample)
    assert 1 + 4 * SAMPLES <= slices <= 1 + 12 * SAMPLES
    assert all(groups > 0 for _, groups, _ in draws)
    assert engine.stats[0].startswith("VoxGI | Sample 0/16 | ")
    assert "Coarse image" in engine.stats[0]
    assert any("Sample 7/16" in line and "| Tile " in line for line in engine.stats)
    assert engine.stats[-1].startswith("VoxGI | Sample 16/16 | Converged in ")
    assert view_state_line(live) == "Converged: 16 of 16 samples"

    converged = draws[-1][0][..., :3]
    f12 = f12_combined(scene, tmp_path)
    error = relative_l1(converged, f12)
    after_one = relative_l1(draws[1 + 5][0][..., :3], f12)  # some tiles of sample 1 in
    # F12's own noise: the same render with another seed
    scene.voxgi.seed += 1
    noise = relative_l1(f12_combined(scene, tmp_path), f12)
    scene.voxgi.seed -= 1
    print(f"converged vs F12 {error:.4f}; early {after_one:.4f}; F12 seed to seed {noise:.4f}")
    # The samples' own denoised gathers averaged were 0.024 off (few rays each: the filter's
    # luminance test refused neighbours); filtering the accumulated gathers gives 0.015, as
    # close as one whole-image sample (the old one-shot view) gets at this filter size
    assert noise < 0.01 and error <= 0.02
    assert error < after_one

    # converged: a redraw draws the kept image and dispatches nothing
    dispatches.take(), dispatches.take_groups()  # F12's
    again = engine_view(engine, scene, depsgraph, view, window)
    assert dispatches.take() == 0 and np.array_equal(again, draws[-1][0])
    assert renderer.shown == "Cached" and engine.stats[-1].startswith("VoxGI | Sample 16/16")


def test_the_first_sample_is_as_smooth_as_f12_under_an_area_light(voxgi, monkeypatch, tmp_path):
    """The gathering samples carry F12's light samples between them, as its gather rays: under
    an area light the view's image after its first sample (a quarter of both in) is already
    near F12's, where one stratum a sample left the penumbrae noisy for most of the samples."""
    scene, depsgraph, view, window, engine, _ = quarter_view(light="AREA")
    image = draw_until_samples(engine, scene, depsgraph, view, window, 1)
    f12 = f12_combined(scene, tmp_path)
    first = relative_l1(image[..., :3], f12)
    print(f"after the first sample vs F12: {first:.4f}")
    assert first < 0.075  # 0.084 with one stratum a sample


def test_a_change_restarts_the_samples_and_the_next_call_draws_an_image(voxgi, monkeypatch):
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.scene.changes import UpdateRecord

    scene = progressive_scene()
    scene.voxgi_viewport.samples = 2
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    dispatches = Dispatches(monkeypatch)
    engine = StandInEngine()
    renderer = quarter_slices(engine)
    limit = 10 ** 9
    first = draw_until_converged(engine, scene, depsgraph, view, window, dispatches, limit)
    first_groups = max(d[1] for d in first)
    still = first[-1][0]

    def next_call(view_matrix):
        redraws = engine.redraws
        image = engine_view(engine, scene, depsgraph, view_matrix, window)
        groups = dispatches.take_groups()
        dispatches.take()
        assert engine.redraws == redraws + 1  # more slices follow
        # one slice, not the image (plus at most one per-pixel pass that makes the shown image
        # from the sums, gpu_accumulation)
        assert 0 < groups <= first_groups + -(-WIDTH // 8) * -(-HEIGHT // 8)
        assert filled(image) > 0.99
        return image

    # a camera move: a coarse image of the new view at once, then tiles over it
    moved = next_call(turned(view, 2.0))
    assert renderer.shown == "Coarse" and renderer.progressive.samples_done == 0
    assert engine.stats[-1].startswith("VoxGI | Sample 0/2 | ") and not np.array_equal(moved, still)
    tile = next_call(turned(view, 2.0))
    assert renderer.shown == "Refining" and "| Tile 1/" in engine.stats[-1]
    # the tile landed on the coarse image: some pixels changed, the rest is the coarse image
    changed = np.abs(tile - moved).sum(-1) > 1e-6
    assert 0.05 < changed.mean() < 0.6

    # an object moves: the session applies new results; the next call restarts
    box = bpy.data.objects["Test Box"]
    box.location.x += 0.2
    depsgraph.update()
    live.update(scene, depsgraph, [UpdateRecord("OBJECT", box.name, transform=True,
                                                object_type="MESH")])
    next_call(turned(view, 2.0))
    assert renderer.shown == "Coarse"

    # a setting: more samples restart too
    draw_until_converged(engine, scene, depsgraph, turned(view, 2.0), window, dispatches, limit)
    scene.voxgi_viewport.samples = 3
    next_call(turned(view, 2.0))
    assert renderer.shown == "Coarse" and engine.stats[-1].startswith("VoxGI | Sample 0/3")

    # without Coarse First Image the previous image stays under the first tile
    scene.voxgi_viewport.coarse_first = False
    before = engine_view(engine, scene, depsgraph, turned(view, 2.0), window)
    dispatches.take(), dispatches.take_groups()
    image = next_call(view)
    assert renderer.shown == "Refining"
    kept = np.abs(image - before).sum(-1) <= 1e-6
    assert 0.3 < kept.mean() < 0.95  # most of the view is the previous image, not grey


def test_a_failed_slice_keeps_the_image_says_why_and_retries_only_after_a_change(voxgi,
                                                                                monkeypatch):
    import voxgi.render.viewport as viewport_module

    scene, depsgraph, view, window, engine, renderer = quarter_view()
    engine_view(engine, scene, depsgraph, view, window)  # the coarse image
    shown = engine_view(engine, scene, depsgraph, view, window)  # a tile over it
    original = viewport_module.tracer

    def failing(*args, **kwargs):
        def trace(*_):
            raise RuntimeError("dispatch lost")
        return trace

    monkeypatch.setattr(viewport_module, "tracer", failing)
    dispatches = Dispatches(monkeypatch)
    redraws = engine.redraws
    for _ in range(2):  # the failure, then a redraw of the same key: no retry
        image = engine_view(engine, scene, depsgraph, view, window)
        assert np.array_equal(image, shown) and engine.redraws == redraws
        assert engine.stats[-1] == "VoxGI | viewport trace failed: RuntimeError: dispatch lost"
        assert renderer.shown == "Previous" and dispatches.take() == 0
    # a change restarts: with a working tracer it draws again
    monkeypatch.setattr(viewport_module, "tracer", original)
    moved = engine_view(engine, scene, depsgraph, turned(view, 2.0), window)
    assert renderer.shown == "Coarse" and renderer.error == "" and filled(moved) > 0.99
    assert engine.stats[-1].startswith("VoxGI | Sample 0/16 | ")


def test_a_slice_runs_over_several_draws_stage_by_stage_to_the_same_image(voxgi, monkeypatch):
    """Staged (the default): a draw runs a slice's stages — the G-buffer, each gather, each
    light's dispatches, the estimate — until it has spent its share of the budget and the
    next draw goes on where it stopped. With a budget of 0 every draw runs one stage: it
    dispatches a few kernels, not a slice's ~20; the view shows the last image meanwhile;
    and the samples converge to the very image whole slices give."""
    from voxgi.blender.viewport_session import live_gi

    scene = progressive_scene()
    scene.voxgi_viewport.samples = 4
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    dispatches = Dispatches(monkeypatch)
    images, most = {}, {}
    for staged in (False, True):
        engine = StandInEngine()
        renderer = quarter_slices(engine)
        renderer.progressive.stage_budget = 0.0 if staged else None
        draws = draw_until_converged(engine, scene, depsgraph, view, window, dispatches,
                                     1 << 40)
        assert renderer.progressive.converged
        images[staged] = draws[-1][0]
        # staged, the first image is staged too (render/viewport_prepare.py): no draw runs a
        # slice whole
        most[staged] = max(calls for _, _, calls in draws)
        if staged:
            slices = renderer.progressive.slices
            assert len(draws) > 3 * slices  # every slice over several draws
            first = next(i for i, (image, _, _) in enumerate(draws) if filled(image) > 0.99)
            assert all(filled(image) > 0.99 for image, _, _ in draws[first:])
    print(f"dispatches per draw: whole slices {most[False]}, staged {most[True]}")
    assert most[True] <= 6 < most[False]
    np.testing.assert_allclose(images[True], images[False], atol=1e-5)


def test_while_every_draw_is_a_new_view_the_dropped_coarse_images_are_not_started(voxgi,
                                                                                  monkeypatch):
    """Orbiting (a new view every draw) with staged slices: the first draw of the orbit starts
    the coarse image of its view; the next views would drop theirs before it could show, so
    their draws trace nothing (no G-buffer, no dispatch) and keep the last image on screen;
    the first draw with the view held still starts the coarse image, which then shows."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gbuffer

    scene = progressive_scene()
    scene.voxgi_viewport.samples = 2
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    dispatches = Dispatches(monkeypatch)
    rasters = []
    original = gbuffer.rasterize  # the slices' G-buffers (gbuffer.rasterize_stages)
    monkeypatch.setattr(gbuffer, "rasterize",
                        lambda *a, **k: (rasters.append(1), original(*a, **k))[1])
    engine = StandInEngine()
    renderer = quarter_slices(engine)
    renderer.progressive.stage_budget = 0.0  # one stage per draw: no draw shows a coarse image
    draw_until_converged(engine, scene, depsgraph, view, window, dispatches, 1 << 40)
    still = engine_view(engine, scene, depsgraph, view, window)

    def work():
        done = len(rasters) + dispatches.take()
        rasters.clear()
        return done

    work()
    images = []
    for step in range(1, 5):  # the orbit
        redraws = engine.redraws
        images.append(engine_view(engine, scene, depsgraph, turned(view, 2.0 * step), window))
        assert engine.redraws == redraws + 1 and filled(images[-1]) > 0.99
        assert work() > 0 if step == 1 else work() == 0, f"orbit draw {step}"
        assert renderer.progressive.coarse_pending
    assert all(np.array_equal(image, still) for image in images)  # the last image stays
    # held still: the next draws start the coarse image and show it
    for draws in range(1, 50):
        image = engine_view(engine, scene, depsgraph, turned(view, 8.0), window)
        if draws == 1:
            assert work() > 0
        if not renderer.progressive.coarse_pending:
            break
    assert renderer.shown == "Coarse" and not np.array_equal(image, still)


def test_the_frame_stays_on_the_gpu_no_draw_reads_anything_back(voxgi, monkeypatch):
    """Issue 19 point 5: the slices' G-buffer, direct light, gathers (Accurate) or cones (Fast),
    the gathers' sums (gpu_gather_sums), the denoiser, the composition (gpu_compose), the
    pass's sums (gpu_accumulation) and the shown image pass from dispatch to dispatch as
    textures: from the first draw to convergence — Accurate with one bounce and with the
    radiance cache's bounces (built in stages), Fast with shadow rays (the default) — no
    ``view_draw`` reads a texture back."""
    import sys

    from voxgi.render import gpu_tracer, viewport

    scene = progressive_scene()
    scene.voxgi_viewport.samples = 4
    depsgraph, _, view, window = live_view(scene)
    reads, inside = [], [False]
    original_read, original_draw = gpu_tracer.read_texture, viewport.view_draw

    def counted_read(texture):
        if inside[0]:
            reads.append((texture.width, texture.height))
        return original_read(texture)

    def counted_draw(*args, **kwargs):
        inside[0] = True
        try:
            return original_draw(*args, **kwargs)
        finally:
            inside[0] = False

    for name, module in list(sys.modules.items()):
        if name.startswith("voxgi.render") and getattr(module, "read_texture", None) \
                is original_read:
            monkeypatch.setattr(module, "read_texture", counted_read)
    monkeypatch.setattr(viewport, "view_draw", counted_draw)
    for quality, bounces in (("ACCURATE", 1), ("ACCURATE", 3), ("FAST", 1)):
        scene.voxgi.quality = quality
        scene.voxgi.bounce_source = "MANUAL"
        scene.voxgi.bounces = bounces
        engine = StandInEngine()
        renderer = quarter_slices(engine)
        renderer.progressive.stage_budget = 0.005  # staged, as the view runs
        draws, redraws = 0, -1
        # until converged (with Bounces 3: on the completed cache, built in chunks sized by
        # their measured time, so their count depends on the machine's load)
        while draws < 20000 and not (renderer.progressive.converged and engine.redraws == redraws
                                     and (bounces == 1 or renderer.cache.generation > 0)):
            redraws = engine.redraws
            engine_view(engine, scene, depsgraph, view, window)
            draws += 1
        assert renderer.progressive.converged and draws > 4 and not renderer.error
        assert reads == [], f"{quality}, Bounces {bounces}: {len(reads)} read-backs in view_draw"
        if bounces > 1:
            assert renderer.cache.texture is not None and renderer.cache._cache is None


def test_a_stage_is_predicted_by_its_longest_recent_run_scaled_to_the_next_tile():
    """A draw stops before a stage that would end past its share of the 30 ms budget, as
    predicted from the slices before: the longest of that stage's last runs, scaled up to the
    next tile's pixels where it ran over fewer (a border tile's short run predicted a whole
    tile's stage, and draws ran to 35–50 ms), never scaled down."""
    from voxgi.render.progressive import STAGE_HISTORY, ProgressiveImage

    image = ProgressiveImage()
    assert image.predicted("tile", 1, 10_000) is None  # never ran
    runs = [(0.004, 10_000), (0.009, 10_000), (0.002, 2_500), (0.005, 10_000)]
    image.stage_seconds[("tile", 1)] = runs[-STAGE_HISTORY:]
    assert image.predicted("tile", 1, 10_000) == 0.009  # the longest, not the last
    assert image.predicted("tile", 1, 20_000) == 0.018  # scaled up to a bigger tile
    assert image.predicted("tile", 1, 1_000) == 0.009   # not down to a smaller one
    assert image.predicted("tile", 1, 0) == 0.009       # pixels unknown
    assert image.predicted("lit tile", 1, 10_000) is None  # a kind of its own


def test_a_tile_where_a_stage_costs_more_than_the_stage_budget_is_cut_in_two():
    """A stage's cost a pixel differs across the view (the emitters' stages by a panel cost
    two to ten times what they cost elsewhere): a tile whose longest stage the view's cost map
    predicts past the stage budget, from what the stages cost where it lies, is traced as
    two, so that one stage does not run the draw past the 30 ms."""
    from voxgi.render.progressive import ProgressiveImage
    from voxgi.voxgi_addon.preview.tile_costs import CostMap

    image = ProgressiveImage()
    image.costs = CostMap(160, 120)
    for y0 in range(0, 120, 40):
        for x0 in range(0, 160, 40):  # 1 µs a pixel on the left half, 12 µs on the right
            image.costs.measured(("tile", 2), (x0, y0, 40, 40), (12e-6 if x0 >= 80 else 1e-6) * 1600)
    cheap, dear = (0, 0, 48, 40), (104, 40, 48, 40)
    assert image.costs.predicted(("tile", 2), cheap) == pytest.approx(1e-6 * 1920)
    assert image.costs.predicted(("tile", 2), dear) == pytest.approx(12e-6 * 1920)
    assert image.stage_budget == pytest.approx(0.015)
    image.tiles, image.tile_count, image.tile_stride = [cheap, dear], 2, 1
    image._split_next("tile")
    assert image.tiles == [cheap, dear]  # 1.9 ms: whole
    image.tiles.pop(0)
    image._split_next("tile")  # 23 ms: two of 24 × 40
    assert image.tiles == [(104, 40, 24, 40), (128, 40, 24, 40)]
    assert image.tile_count == 3
    image.tiles, image.fixed_pixels = [dear], 1920  # a test's fixed slices stay whole
    image._split_next("tile")
    assert image.tiles == [dear]


def test_the_coarse_image_is_sized_by_its_whole_work_with_the_views_aspect():
    """The view waits for its coarse first image, over as many draws as its stages take: it is
    sized so that all its stages together take about ``COARSE_WORK``, with the view's aspect.
    Before, it was sized by its longest stage, and any size over a quarter of the view became
    exactly half its width and height: on the demo scene a 320 × 180 view's coarse image was
    160 × 90, 115–170 ms of stages over 9–10 draws (now 49–85 ms to the first image)."""
    import types

    from voxgi.render.gpu_shaders import LOCAL_SIZE
    from voxgi.render.progressive import COARSE_WORK, ProgressiveImage
    from voxgi.voxgi_addon.preview.progressive import SliceSizer

    image = ProgressiveImage()
    image.sizers = {kind: SliceSizer(0.015, first_pixels=2304, least=2304, amortize=False)
                    for kind in ("tile", "lit tile", "coarse")}
    image.sizers["coarse"].budget = COARSE_WORK
    image.accumulation = types.SimpleNamespace(width=320, height=180)
    image.sizers["tile"].measured(12_000, 0.012)  # tiles of 12,000 pixels fit their stages
    image.sizers["tile"].measured(6_000, 0.006)
    assert image.coarse_size(1) == (160, 88)  # none measured yet: about half of both sides
    # one coarse image measured: 14,400 pixels in 3 × COARSE_WORK of stages → about a third
    image.sizers["coarse"].measured(14_400, 3 * COARSE_WORK)
    w, h = image.coarse_size(1)
    assert abs(w * h - 4_800) < 0.15 * 4_800 and abs(w / h - 320 / 180) < 0.25, (w, h)
    # sides of the tiles' kind: whole work groups of the gather grid, no power of two
    assert w % LOCAL_SIZE == 0 and h % LOCAL_SIZE == 0 and w & (w - 1) and h & (h - 1)
    # two sizes measured: their fit (10 ms fixed, the rest a pixel) → 16,000 pixels in
    # COARSE_WORK, more than a quarter of the view: at most half its width and height
    per_pixel = (COARSE_WORK - 0.010) / 16_000
    image.sizers["coarse"].samples = [(p, 0.010 + per_pixel * p) for p in (6_400, 14_400)]
    assert image.coarse_size(1) == (160, 88)
    # and 8,000 pixels with the view's aspect, at a third of the GI resolution
    per_pixel = (COARSE_WORK - 0.010) / 8_000
    image.sizers["coarse"].samples = [(p, 0.010 + per_pixel * p) for p in (6_400, 14_400)]
    w, h = image.coarse_size(3)
    assert abs(w * h - 8_000) < 0.15 * 8_000 and abs(w / h - 320 / 180) < 0.25, (w, h)
    assert w % (3 * LOCAL_SIZE) == 0 and h % (3 * LOCAL_SIZE) == 0
    assert (w // 3) & (w // 3 - 1) and (h // 3) & (h // 3 - 1)


def test_the_first_sample_gathers_at_one_cell_in_four_and_lands_as_near_f12(voxgi, monkeypatch,
                                                                             tmp_path):
    """The view's first sample traces its diffuse gather at the lattice of the grid's cells
    (odd row, odd column) with twice its rays, the other cells holes the filter fills; the
    later samples gather at every cell. After that sample the view lies about as near F12's
    image as a first sample gathered at every cell, for half its diffuse gather's rays."""
    import voxgi.render.gpu_preview as gpu_preview
    from voxgi.render import progressive
    from voxgi.voxgi_addon.preview.progressive import LATTICE_RAYS

    calls = []
    original = gpu_preview.gather_steps

    def recorded(*args, **kwargs):
        if kwargs.get("kernel") == "bvh_gather":
            calls.append((kwargs.get("lattice", False), args[5].rays))
        return (yield from original(*args, **kwargs))

    monkeypatch.setattr(gpu_preview, "gather_steps", recorded)
    scene, depsgraph, view, window, engine, _ = quarter_view()
    f12 = f12_combined(scene, tmp_path)
    rays = scene.voxgi.gi_rays // 4  # over the 4 gathering samples of 16
    first = {}
    for lattice in (False, True):
        monkeypatch.setattr(progressive, "LATTICE_FIRST", lattice)
        quarter_slices(engine)  # a new view of the same scene
        calls.clear()
        image = draw_until_samples(engine, scene, depsgraph, view, window, 1)
        sampled = calls[1:]  # (the first: the coarse image's own gather)
        expected = (True, LATTICE_RAYS * rays) if lattice else (False, rays)
        assert sampled and all(c == expected for c in sampled)
        first[lattice] = relative_l1(image[..., :3], f12)
        calls.clear()
        draw_until_samples(engine, scene, depsgraph, view, window, 2, limit=20)
        assert calls and all(c == (False, rays) for c in calls)  # every cell from the second
    print(f"after the first sample vs F12: every cell {first[False]:.4f}, "
          f"the lattice {first[True]:.4f}")
    assert first[True] <= 1.1 * first[False]


def textured_view(tmp_path):
    """(scene, depsgraph, view, window, F12's Combined) of the textured room at the test's
    size, its view at full resolution with the test's samples and Cycles' default filter."""
    import texture_scenes

    scene = bpy.context.scene
    texture_scenes.build_textured_room(scene)
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.cycles.filter_width = 1.5  # Cycles' default
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = SAMPLES
    depsgraph, _, view, window = live_view(scene)
    bake_queued(scene)  # the back wall's checker: the view's first image waits for it
    f12 = f12_combined(scene, tmp_path)
    return scene, depsgraph, view, window, f12


def test_a_samples_textures_are_its_pixels_own_squares_as_f12s(voxgi, monkeypatch, tmp_path):
    """A view's sample moves its camera rays sub-pixel (the samples anti-alias the edges) but
    takes its textures over its pixels' own squares, as F12's centre pass does: on the
    textured room the view after its first sample lies near F12's image. Textures
    point-sampled at each sample's moved rays (as before) put the checkers' edges a texel's
    jump away from F12's until many samples were in."""
    import voxgi.render.gpu_preview as gpu_preview

    scene, depsgraph, view, window, f12 = textured_view(tmp_path)
    engine = StandInEngine()
    original = gpu_preview.rasterize_stages

    def at_points(*args, **kwargs):  # a sample's textures at its moved rays' points
        if tuple(kwargs.get("tap_shift", (0.0, 0.0))) != (0.0, 0.0):
            kwargs.update(filter_width=0.0, tap_shift=(0.0, 0.0))
        return original(*args, **kwargs)

    first = {}
    for squares in (True, False):
        monkeypatch.setattr(gpu_preview, "rasterize_stages", original if squares else at_points)
        quarter_slices(engine)  # a new view of the same scene
        image = draw_until_samples(engine, scene, depsgraph, view, window, 1)
        first[squares] = relative_l1(image[..., :3], f12)
    print(f"after the first sample vs F12: the pixels' squares {first[True]:.4f}, "
          f"the moved rays' points {first[False]:.4f}")
    assert first[True] < 0.075  # 0.114 at the moved rays' points


def test_across_a_textures_steps_the_samples_take_the_filters_mean(voxgi, monkeypatch, tmp_path):
    """A view's samples take their textures over their pixels' own squares, so across a step
    of a surface's texture (the checkers' edges) a sample goes into its neighbour by the pixel
    filter's mean weight, not by its offset's: on the textured room the view's early samples
    then lie near F12's image instead of swinging the checkers' edges sample by sample, and
    the converged view lies nearer too."""
    import voxgi.render.progressive as progressive

    scene, depsgraph, view, window, f12 = textured_view(tmp_path)
    engine = StandInEngine()
    errors = {}
    for mean in (True, False):
        monkeypatch.setattr(progressive, "MEAN_TAILS", mean)
        quarter_slices(engine)  # a new view of the same scene
        errors[mean] = [relative_l1(draw_until_samples(engine, scene, depsgraph, view, window,
                                                       samples)[..., :3], f12)
                        for samples in (1, 2, 3, 4, SAMPLES)]
    print("vs F12 after samples 1, 2, 3, 4, 16: the filter's mean across texture steps "
          + " ".join(f"{e:.4f}" for e in errors[True]) + "; the offsets' weights "
          + " ".join(f"{e:.4f}" for e in errors[False]))
    # by the offsets' weights alone: 0.0531, then 0.0388 0.0412 0.0360
    assert errors[True][0] < 0.05
    assert max(errors[True][1:4]) < 0.036
    assert errors[True][-1] < 0.03        # 0.0258 (the offsets' 0.0271)

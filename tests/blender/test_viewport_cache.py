"""The viewport's radiance cache is built a chunk of voxel faces per stage
(``render/viewport_cache.py``): the staged build gives the whole build's cache, no stage runs
more than one chunk's gather, and the viewport reads the last complete cache (or one bounce)
while a new one is built, restarting its image when it completes."""
from __future__ import annotations

import time

import bounce_scenes
import bpy
import numpy as np


def cornell_inputs(settings):
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.render import gpu_context
    from voxgi.render.gpu_bvh import shared_bvh
    from voxgi.voxgi_addon.gi.light_injection import material_emission
    from voxgi.voxgi_addon.gi.world_light import scene_lights
    from voxgi.voxgi_addon.preview.passes import principled_table
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    bounce_scenes.build("cornell_box", bpy.context.scene)
    assert gpu_context.ensure_gpu_context()[0]
    snapshot, _ = snapshot_or_error(bpy.context, bpy.context.evaluated_depsgraph_get())
    tris = world_triangles(snapshot)
    emission = material_emission(snapshot)
    return (shared_bvh().update(tris), scene_lights(snapshot, tris, emission),
            principled_table(snapshot), emission, settings)


def test_the_staged_build_is_the_whole_build_a_chunk_per_stage(voxgi, monkeypatch):
    import gpu

    from voxgi.render import gpu_gather
    from voxgi.render.gpu_gather import cache_stages
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    inputs = cornell_inputs(GatherSettings(bounces=3, cache_resolution=16, cache_rays=8))
    calls = []
    original = gpu.compute.dispatch
    monkeypatch.setattr(gpu.compute, "dispatch",
                        lambda *a, **k: (calls.append(1), original(*a, **k))[1])
    whole, _ = gpu_gather.cache_gpu(*inputs)
    # the rays traced once (one chunk), then two lookup passes per iteration (the second's
    # glossy shares read the first, radiance_cache.relax) and two more for the next
    # iteration (radiance_cache.one_more_bounce)
    assert len(calls) == 1 + 2 * 2 + 2
    calls.clear()
    stages, per_stage = cache_stages(*inputs, budget=0.0), []
    while True:  # budget 0: one row of rays per stage
        try:
            next(stages)
        except StopIteration as end:
            staged, _ = end.value
            break
        per_stage.append(len(calls))
        calls.clear()
    print(f"{len(per_stage)} stages, at most {max(per_stage)} dispatches each")
    # every stage one chunk of the rays or one iteration's lookups: one dispatch
    assert len(per_stage) > 4 and max(per_stage) == 1
    for part in ("faces", "ahead"):
        a, b = (np.concatenate(getattr(c, part)).astype(np.float64) for c in (staged, whole))
        assert b.mean() > 0.01
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)


def test_the_viewport_reads_one_bounce_then_the_cache_and_restarts_when_it_completes(voxgi):
    from voxgi.render.viewport_cache import ViewportCache
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    inputs = cornell_inputs(GatherSettings(bounces=3, cache_resolution=16, cache_rays=8))
    cache = ViewportCache(budget=0.0)
    got, stages = [], 0
    while cache.generation == 0 and stages < 10000:
        stage = cache.stage(*inputs)
        while True:
            try:
                next(stage)
                stages += 1
            except StopIteration as end:
                got.append(end.value)
                break
    assert cache.generation == 1 and stages > 1
    assert all(texture is None for texture in got[:-1])  # one bounce until complete
    assert got[-1] is not None
    # the same scene again: the complete cache at once, no stage
    stage = cache.stage(*inputs)
    try:
        next(stage)
        raise AssertionError("a complete cache ran another stage")
    except StopIteration as end:
        assert end.value is got[-1]


def converged_means(quality: str) -> dict:
    """{bounces: mean linear colour of the converged Rendered view} of the Cornell box in
    ``quality`` at Bounces 1 and 3 (2 samples, full resolution), each view drawn until it
    stops asking for redraws; checks that it converged and built the cache only for 3."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, cornell, engine_view, gpu_ready

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.viewport import ViewportRenderer

    scene = cornell()
    scene.voxgi.quality = quality
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = 2
    scene.voxgi.bounce_source = "MANUAL"
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    means = {}
    for bounces in (1, 3):
        scene.voxgi.bounces = bounces
        engine = StandInEngine()
        renderer = engine.voxgi_viewport = ViewportRenderer()
        image, draws = None, 0
        while draws < 5000:
            redraws = engine.redraws
            image = engine_view(engine, scene, depsgraph, view, window)
            draws += 1
            if engine.redraws == redraws:
                break
        assert renderer.progressive.converged, f"not converged after {draws} draws"
        assert renderer.cache.generation == (1 if bounces > 1 else 0)
        assert image is not None
        means[bounces] = float(renderer.progressive.read_image()[..., :3].mean())  # linear, before display
        print(f"{quality}, bounces {bounces}: {draws} draws, mean {means[bounces]:.4f}")
    return means


def test_the_view_shows_more_bounces_once_its_cache_is_built(voxgi):
    """Bounces 3 in the Rendered view: draws run the cache's build a chunk at a time (one
    bounce meanwhile), the completed cache restarts the image, and the converged view is
    brighter than the one-bounce view, as F12's is."""
    means = converged_means("ACCURATE")
    assert means[3] > 1.05 * means[1]


def test_the_view_at_cycles_diffuse_1_builds_the_glossy_bounces_cache(voxgi):
    """Follow Cycles at Diffuse 1 (Glossy 4, Total 12): the Rendered view builds the cache
    whose first iteration a glossy scatter carries past the one diffuse bounce (docs/
    gi_pipeline.md "One bounce and Cycles' glossy bounces"), a chunk per draw as at more
    bounces, and converges brighter than Manual Bounces 1."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, cornell, engine_view, gpu_ready

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.viewport import ViewportRenderer

    scene = cornell()
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = 2
    scene.cycles.diffuse_bounces, scene.cycles.glossy_bounces, scene.cycles.max_bounces = 1, 4, 12
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    means, caches = {}, {}
    for source in ("MANUAL", "CYCLES"):
        scene.voxgi.bounce_source, scene.voxgi.bounces = source, 1
        engine = StandInEngine()
        renderer = engine.voxgi_viewport = ViewportRenderer()
        draws = 0
        while draws < 5000:
            redraws = engine.redraws
            engine_view(engine, scene, depsgraph, view, window)
            draws += 1
            if engine.redraws == redraws:
                break
        assert renderer.progressive.converged, f"not converged after {draws} draws"
        caches[source] = renderer.cache.generation
        means[source] = float(renderer.progressive.read_image()[..., :3].mean())
    print(means, caches)
    assert caches == {"MANUAL": 0, "CYCLES": 1}
    assert means["CYCLES"] > 1.01 * means["MANUAL"]


def test_fast_quality_in_the_view_builds_its_cache_in_stages_too(voxgi, monkeypatch):
    """Fast quality at Bounces 3 in the Rendered view: its voxels reflect the view's staged
    cache (one bounce until it completes), so no draw builds the whole cache as F12 does
    (``gpu_fast._radiance_cache`` never runs), and the converged view is brighter than the
    one-bounce view."""
    from voxgi.render import gpu_fast

    def whole_build(_scene, settings):
        if settings.bounces > 1:
            raise AssertionError("a draw built the whole radiance cache")

    monkeypatch.setattr(gpu_fast, "_radiance_cache", whole_build)
    means = converged_means("FAST")
    assert means[3] > 1.05 * means[1]


def test_fast_bounces_are_made_on_the_worker_while_the_view_keeps_its_image(voxgi, interactive,
                                                                            monkeypatch):
    """Fast quality at Bounces 3, as in a UI session: no draw rebuilds an octree
    (``cone_octrees`` with a cache never runs on the main thread; the worker runs it). The
    draw after the cache completes hands the rebuild to the worker and the view keeps its
    image (same key, no trace restarted) until the worker is done; then the image restarts
    with the bounces and converges brighter than the one-bounce image before. An object
    moved afterwards comes with its bounced voxels from the update job: no second job, no
    one-bounce image between."""
    import threading

    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, cornell, engine_view, gpu_ready

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_fast, viewport_bounces
    from voxgi.render.viewport import ViewportRenderer
    from voxgi.voxgi_addon.gi import cone_bounces
    from voxgi.voxgi_addon.scene.changes import UpdateRecord

    jobs = interactive
    builds = []  # (on the main thread?) per octree rebuilt with a cache
    original_build, original_cones = cone_bounces.build_octree, gpu_fast.cone_octrees

    def build_octree(*args, **kwargs):
        builds.append(threading.current_thread() is threading.main_thread())
        return original_build(*args, **kwargs)

    def cone_octrees(state, cache):
        assert cache is None, "a draw rebuilt the bounced octrees on the main thread"
        return original_cones(state, cache)

    monkeypatch.setattr(cone_bounces, "build_octree", build_octree)
    monkeypatch.setattr(gpu_fast, "cone_octrees", cone_octrees)
    gate = threading.Event()  # holds the worker's rebuild until the test has looked
    original_volumes = viewport_bounces.bounced_volumes

    def gated(state, cache):
        assert gate.wait(60)
        return original_volumes(state, cache)

    monkeypatch.setattr(viewport_bounces, "bounced_volumes", gated)

    scene = cornell()
    scene.voxgi.quality = "FAST"
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = 2
    scene.voxgi.bounce_source = "MANUAL"
    scene.voxgi.bounces = 3
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    jobs.synchronous = True
    live.update(scene, depsgraph)
    jobs.synchronous = False
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    renderer = engine.voxgi_viewport = ViewportRenderer()

    def draw():
        redraws = engine.redraws
        image = engine_view(engine, scene, depsgraph, view, window)
        jobs.drain()
        return image, engine.redraws > redraws

    # one bounce (no cache yet) converges while the cache is built a chunk per draw (its
    # layout made on the preparing thread: draws until it is, as a user's view goes on
    # drawing, with a moment between them for that thread; the deadline only ends a hang)
    one_bounce = None
    deadline = time.monotonic() + 300.0
    while time.monotonic() < deadline:
        key = renderer.progressive.key
        image, more = draw()
        if renderer.progressive.converged and renderer.cache.generation == 0:
            one_bounce = renderer.progressive.read_image()[..., :3].mean()
        if renderer.cache.generation == 1:
            break
        time.sleep(0.002)
    assert renderer.cache.generation == 1 and one_bounce is not None
    # the cache is complete: the next draw hands its octrees to the worker, and the view
    # keeps its image meanwhile
    assert renderer.progressive.key == key
    kept = image
    for _ in range(3):
        image, more = draw()
        assert renderer.progressive.key == key and np.array_equal(image, kept)
        assert renderer.bounces.pending
    assert builds == []  # nothing rebuilt yet: the worker waits at the gate
    gate.set()
    assert renderer.bounces.job.wait(60) and jobs.drain()  # the timer's drain: a redraw
    traces = renderer.traces
    for draws in range(5000):
        image, more = draw()
        if not more:
            break
    assert renderer.progressive.key != key and renderer.traces > traces
    assert renderer.progressive.converged and renderer.bounced is not None
    bounced = renderer.progressive.read_image()[..., :3].mean()
    print(f"Fast in the view: one bounce {one_bounce:.4f}, Bounces 3 {bounced:.4f}; octree "
          f"builds {builds}")
    assert bounced > 1.05 * one_bounce
    assert builds and not any(builds)  # rebuilt, and never on the main thread

    # an object moves: the update job makes the new state's bounced voxels beside its octree
    box = bpy.data.objects["Test Box"]
    box.location.x += 0.1
    depsgraph.update()
    job = live.update(scene, depsgraph, [UpdateRecord("OBJECT", box.name, transform=True,
                                                      object_type="MESH")])
    assert jobs.wait_idle(60)
    assert live.bounced is not None and live.bounced.fits(live.staged.state)
    before = renderer.bounces.job
    draw()
    assert renderer.bounced is live.bounced and renderer.bounces.job is before
    assert not any(builds), job


class AccurateView:
    """The Cornell box in an Accurate Rendered view at Bounces 3 (2 samples, full resolution,
    a whole slice per draw, the coarse first image on), drawn with the stand-in engine."""

    def __init__(self):
        from stand_in_engine import StandInEngine
        from test_viewport import camera_matrices, cornell, gpu_ready

        from voxgi.blender.viewport_session import live_gi
        from voxgi.render.viewport import ViewportRenderer

        self.scene = scene = cornell()
        scene.voxgi_viewport.resolution_fraction = 1.0
        scene.voxgi_viewport.samples = 2
        scene.voxgi_viewport.coarse_first = True
        scene.voxgi.bounce_source = "MANUAL"
        scene.voxgi.bounces = 3
        gpu_ready()
        self.depsgraph = bpy.context.evaluated_depsgraph_get()
        self.live = live_gi(scene.name_full)
        self.live.update(scene, self.depsgraph)
        self.view, self.window = camera_matrices(scene, self.depsgraph)
        self.engine = StandInEngine()
        self.renderer = self.engine.voxgi_viewport = ViewportRenderer()
        self.renderer.progressive.stage_budget = None  # a whole slice per draw

    def draw(self) -> bool:
        """One view_draw; whether it asked for another."""
        from test_viewport import engine_view

        redraws = self.engine.redraws
        engine_view(self.engine, self.scene, self.depsgraph, self.view, self.window)
        return self.engine.redraws != redraws

    def draw_until_still(self, each=None) -> None:
        """Draw until the view stops asking for redraws (``each()`` before every draw returns
        what to call after it, or None)."""
        for _ in range(5000):
            after = each() if each is not None else None
            more = self.draw()
            if after is not None:
                after()
            if not more:
                return
        raise AssertionError("the view never stopped asking for redraws")

    def move_box(self) -> None:
        from voxgi.voxgi_addon.scene.changes import UpdateRecord

        box = bpy.data.objects["Test Box"]
        box.location.x += 0.1
        self.depsgraph.update()
        self.live.update(self.scene, self.depsgraph, [UpdateRecord(
            "OBJECT", box.name, transform=True, object_type="MESH")])


def test_the_first_image_of_a_change_does_not_start_the_new_cache(voxgi):
    """An object moves under a complete cache (Accurate, Bounces 3): the coarse first image
    of the change reads the last complete cache and starts no build (its first chunk, the
    layout, took 0.3 s of the first image on the demo scene); the tiles after it do."""
    view = AccurateView()
    renderer = view.renderer
    view.draw_until_still()
    assert renderer.cache.generation == 1 and renderer.cache.building is None
    complete = renderer.cache.texture

    view.move_box()
    view.draw()
    assert renderer.shown == "Coarse"
    assert renderer.cache.building is None and renderer.cache.texture is complete
    view.draw()
    assert renderer.shown == "Refining" and renderer.cache.building is not None


def test_accurate_tiles_wait_for_the_cache_and_a_stale_build_is_not_run(voxgi):
    """Accurate, Bounces 3: a completed cache restarts the image, so once a tile has asked for
    a new cache the draws build it a chunk each and trace no tile until it is complete (before,
    every tile traced meanwhile was dropped); and a build asked for by an image the scene has
    since left is not run ahead of the tiles: after two quick moves only the last one's cache
    is completed."""
    view = AccurateView()
    renderer = view.renderer
    renderer.cache.budget = 0.0  # the build in many chunks
    counts = {"chunks": 0, "tiles": 0}

    def each():
        traces, building = renderer.traces, renderer.cache.building is not None

        def after():
            if building and renderer.cache.generation == 0:
                counts["chunks"] += "radiance cache stage" in renderer.timings
                counts["tiles"] += renderer.traces > traces
        return after

    view.draw_until_still(each)
    assert renderer.progressive.converged and renderer.cache.generation == 1
    print(f"{counts['chunks']} chunks ahead of the tiles, {counts['tiles']} tiles meanwhile")
    assert counts["chunks"] > 3 and counts["tiles"] == 0

    view.scene.voxgi_viewport.coarse_first = False  # a change's first draw traces a tile
    for _ in range(2):  # two moves: the first one's build is left behind by the second
        view.move_box()
        view.draw()  # a tile asks for its cache
        assert renderer.cache.building is not None
    view.draw_until_still()
    assert renderer.progressive.converged
    assert renderer.cache.generation == 2  # the last move's cache, not the first's as well


def test_a_draw_runs_as_many_chunks_of_the_build_as_its_stage_budget_holds(voxgi):
    """The build's chunks (a relaxation pass of the box's cache is 1-2 ms) share a draw while
    the next one fits the slices' stage budget, and a draw that compiled a kernel runs no
    more: with the budget held at nothing the build takes a draw a chunk, with a budget that
    holds it all a draw or two; either way the view converges on the complete cache (the
    staged build equals the whole one: ``test_the_staged_build_is_the_whole_build_a_chunk_per
    _stage``)."""

    def cache_draws(stage_budget):
        view = AccurateView()
        renderer = view.renderer
        renderer.progressive.stage_budget = stage_budget
        renderer.cache.budget = 0.0  # the build in many chunks
        counted = {"draws": 0}

        def each():
            def after():
                counted["draws"] += "radiance cache stage" in renderer.timings
            return after

        view.draw_until_still(each)
        assert renderer.progressive.converged and renderer.cache.generation == 1
        assert renderer.cache.building is None and renderer.cache.texture is not None
        return counted["draws"]

    one_each, shared = cache_draws(1e-9), cache_draws(60.0)
    print(f"the build's draws: {one_each} a chunk each, {shared} sharing them")
    assert one_each > 8 and shared <= 2


def test_advance_any_says_whether_a_chunk_ran(voxgi):
    """``ViewportCache.advance_any`` (the converged view's build, chunks sharing a draw) runs a
    chunk of the build under way and says so; with none under way, nothing: the draw's loop
    then stops instead of spinning."""
    from voxgi.render.viewport_cache import ViewportCache
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    inputs = cornell_inputs(GatherSettings(bounces=3, cache_resolution=16, cache_rays=8))
    cache = ViewportCache(budget=0.0)
    assert not cache.advance_any()  # nothing to build
    stage = cache.stage(*inputs)
    next(stage)  # the build's first chunk
    chunks = 1
    while cache.generation == 0 and chunks < 10000:
        assert cache.advance_any()
        chunks += 1
    assert cache.generation == 1 and chunks > 4
    assert cache.building is None and not cache.advance_any()


def test_a_completed_cache_restarts_the_image_without_a_second_coarse_image(voxgi):
    """A fresh view (Accurate, Bounces 3, Coarse First Image on) shows a coarse image while
    its radiance cache is built; the cache's completion restarts the image, and the image so
    far stays the backdrop until the tiles cover it: no second coarse image (it cost the box's
    fresh view 3–5 draws; docs/gi_pipeline.md "A coarse image sized by its whole work").
    A view change still starts with one."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, cornell, engine_view, gpu_ready, turned

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.viewport import ViewportRenderer

    scene = cornell()
    scene.voxgi.quality = "ACCURATE"
    scene.voxgi.bounce_source = "MANUAL"
    scene.voxgi.bounces = 3
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.samples = 2
    scene.voxgi_viewport.coarse_first = True
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    engine = StandInEngine()
    renderer = engine.voxgi_viewport = ViewportRenderer()

    def slices_until_converged(view_matrix):
        """The kinds of the slices finished, with the cache's generation when each did."""
        finished, traces, draws = [], renderer.traces, 0
        while draws < 5000:
            redraws = engine.redraws
            engine_view(engine, scene, depsgraph, view_matrix, window)
            draws += 1
            if renderer.traces != traces:
                traces = renderer.traces
                finished.append((renderer.progressive.last.kind, renderer.cache.generation))
            if engine.redraws == redraws:
                break
        assert renderer.progressive.converged, f"not converged after {draws} draws"
        return finished

    fresh = slices_until_converged(view)
    assert renderer.cache.generation == 1
    coarse = [generation for kind, generation in fresh if kind == "coarse"]
    assert coarse == [0], fresh  # the one-bounce coarse image, none with the cache
    assert any(kind == "tile" and generation == 1 for kind, generation in fresh), fresh
    changed = slices_until_converged(turned(view, 2.0))
    assert changed[0][0] == "coarse" and [k for k, _ in changed].count("coarse") == 1, changed


def test_f12_and_the_rendered_view_share_one_radiance_cache(voxgi, monkeypatch):
    """A view entered after F12 reads F12's radiance cache, F12 after a view reads the view's,
    and a view switched off and on again reads the one it built: none builds it again, and
    F12's image over the view's cache is F12's over its own (the two builds are one cache)."""
    from stand_in_engine import StandInEngine
    from test_viewport import camera_matrices, cornell, engine_view, gpu_ready

    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_gather, viewport_cache
    from voxgi.render.pipeline import render_scene_passes
    from voxgi.render.viewport import ViewportRenderer

    scene = cornell()
    scene.voxgi.quality = "ACCURATE"
    scene.voxgi_viewport.samples = 1
    scene.voxgi.bounce_source = "MANUAL"
    scene.voxgi.bounces = 3
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live_gi(scene.name_full).update(scene, depsgraph)
    view, window = camera_matrices(scene, depsgraph)
    built = {"view": 0, "f12": 0}
    stages, whole = viewport_cache.cache_stages, gpu_gather.cache_gpu
    monkeypatch.setattr(viewport_cache, "cache_stages",
                        lambda *a, **k: (built.__setitem__("view", built["view"] + 1),
                                         stages(*a, **k))[1])
    monkeypatch.setattr(gpu_gather, "cache_gpu",
                        lambda *a, **k: (built.__setitem__("f12", built["f12"] + 1),
                                         whole(*a, **k))[1])

    def converged_view():
        engine = StandInEngine()
        renderer = engine.voxgi_viewport = ViewportRenderer()
        for _ in range(5000):
            redraws = engine.redraws
            engine_view(engine, scene, depsgraph, view, window)
            if engine.redraws == redraws:
                break
        assert renderer.progressive.converged and renderer.cache.generation == 1
        return renderer

    def f12():
        passes, _ = render_scene_passes(bpy.context, scene, None, 48, 36)
        return np.asarray(passes["Combined"], np.float64)

    gpu_gather.drop_shared_cache()  # as after an edit
    first = converged_view()
    assert built == {"view": 1, "f12": 0}
    over_views = f12()  # F12 after the view: the view's cache
    assert built == {"view": 1, "f12": 0}
    assert gpu_gather.shared_cache(*first.cache.key)[1] is first.cache.texture
    again = converged_view()  # the view switched off and on: no build
    assert built == {"view": 1, "f12": 0} and again.cache.texture is first.cache.texture
    gpu_gather.drop_shared_cache()
    own = f12()  # F12 building its own
    assert built == {"view": 1, "f12": 1}
    assert own.mean() > 0.01
    np.testing.assert_allclose(over_views, own, rtol=1e-5, atol=1e-6)
    after = converged_view()  # a view entered after F12: F12's cache, no build
    assert built == {"view": 1, "f12": 1}
    assert after.cache.texture is gpu_gather.shared_cache(*after.cache.key)[1]
    assert after.cache.cache is not None  # F12's read-back cache, for Fast's voxels
    bpy.ops.wm.read_factory_settings(use_empty=True)  # another file: its own cache
    assert gpu_gather.shared_cache(*after.cache.key) is None


def test_fast_quality_reads_the_sessions_radiance_cache(voxgi, monkeypatch):
    """Fast quality's F12 takes the session's cache (here a view's, read back once) and builds
    none; what it reads is the cache it builds itself."""
    import types

    from voxgi.render import gpu_fast, gpu_gather
    from voxgi.render.viewport_cache import ViewportCache
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    bvh, lights, principled, emission, settings = cornell_inputs(
        GatherSettings(bounces=3, cache_resolution=16, cache_rays=8))
    scene = types.SimpleNamespace(
        bvh=bvh, lights=lights, principled=principled, emission=emission,
        gather_tables=lambda: gpu_gather.gather_tables(lights, principled, emission))
    gpu_gather.drop_shared_cache()
    view = ViewportCache()
    for _ in range(10000):
        if view.generation:
            break
        list(view.stage(bvh, lights, principled, emission, settings))  # one stage
    assert view.generation == 1
    built, whole = [], gpu_fast.cache_gpu
    monkeypatch.setattr(gpu_fast, "cache_gpu",
                        lambda *a, **k: (built.append(1), whole(*a, **k))[1])
    taken = gpu_fast._radiance_cache(scene, settings)
    assert built == [] and taken is not None and not callable(taken)
    assert gpu_fast._radiance_cache(scene, settings) is taken  # read back once
    gpu_gather.drop_shared_cache()
    own = gpu_fast._radiance_cache(scene, settings)
    assert built == [1]
    for part in ("faces", "ahead"):
        a, b = (np.concatenate(getattr(c, part)).astype(np.float64) for c in (taken, own))
        assert b.mean() > 0.01
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)

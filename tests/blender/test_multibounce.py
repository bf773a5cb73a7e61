"""Issue 20 acceptance: multi-bounce light through the radiance cache (voxgi_addon/gi/
radiance_cache.py). At the default Bounces (Follow Cycles: 4 diffuse bounces) the preview
lands close to Cycles at its **default** light paths (tests/data/bounce_refs, made by
tools/make_bounce_references.py); the thin-wall dark room stays dark; the GPU's cache and
passes equal the numpy reference's within 2%.

The other Blender tests run at Bounces = 1 (tests/blender/conftest.py
``one_bounce_by_default``): their one-bounce references and limits are unchanged.
"""
from __future__ import annotations

import json
import pathlib

import bounce_scenes
import bpy
import numpy as np
import pytest
import scenes

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "bounce_refs"
LIMITS = json.loads((REFS / "limits.json").read_text())
PASSES = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect")
# Diffuse Indirect summed over the image, against Cycles': 2.3–4.1% short on three of the four
# scenes while the cache counted a glossy scatter as a diffuse bounce
# (docs/gi_pipeline.md "Glossy scatters between diffuse bounces")
INDIRECT_SUM_TOLERANCE = 0.02


def relative_l1(ours, reference, mask):
    return float(np.abs(ours[mask] - reference[mask]).sum() /
                 max(np.abs(reference[mask]).sum(), 1e-12))


def preview(tmp_path, scene, width, height, tracer="AUTO"):
    from voxgi.blender.session import scene_session
    from voxgi.voxgi_addon.files.exr import read_exr

    scene.voxgi.tracer = tracer
    path = tmp_path / f"preview_{tracer}.exr"
    assert bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=width,
                                        resolution_y=height) == {"FINISHED"}
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy")
    channels = read_exr(path)
    return {p: np.stack([channels[f"{p}.{c}"] for c in "RGB"], axis=-1).astype(np.float64)
            for p in PASSES}


def follow_cycles(scene):
    """The default Bounces (the tests' conftest starts scenes at one bounce)."""
    from voxgi.blender.settings import diffuse_bounces, trace_options

    scene.voxgi.bounce_source = "CYCLES"
    assert diffuse_bounces(scene.voxgi) == 4  # a new scene's Cycles Light Paths
    assert trace_options(scene.voxgi, 160, 120)["gather_settings"].bounces == 4


@pytest.mark.parametrize("name", list(bounce_scenes.SCENES))
def test_default_bounces_match_cycles_default_light_paths(voxgi, tmp_path, name):
    scene = bpy.context.scene
    bounce_scenes.build(name, scene)
    follow_cycles(scene)
    ours = preview(tmp_path, scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT)
    reference = np.load(REFS / f"{name}.npz")
    mask = reference["Alpha"] > 0.5
    errors = {p: relative_l1(ours[p], reference[p].astype(np.float64), mask) for p in PASSES}
    # the light of the later bounces as much as Cycles': a glossy scatter between diffuse
    # bounces does not count toward its Diffuse limit (radiance_cache.relax)
    indirect = "Diffuse Indirect"
    brightness = ours[indirect][mask].sum() / reference[indirect][mask].sum()
    print(name, {p: round(e, 4) for p, e in errors.items()}, f"{indirect} sum {brightness:.4f}")
    for pass_name, limit in LIMITS[name].items():
        assert errors[pass_name] <= limit, (pass_name, errors)
    assert abs(brightness - 1.0) <= INDIRECT_SUM_TOLERANCE, brightness


# The box's Diffuse Indirect × Diffuse Color against Cycles', per region of a 6 × 8 grid, as
# a share of the region's Combined: the bounce hits' glossy lobes followed one reflection
# further (exact_indirect.lobe_follow_chance) where they read the cache's light as uniform
# over the lobe before (docs/gi_pipeline.md "Where the box's regional bias comes from: the
# hits' glossy lobes"): the back wall (rows 1-4, columns 2-5) read +0.86% on average and the
# regions 0.67% apart from Cycles'; now -0.03% and 0.43%
BACK_WALL_BIAS = 0.004
REGIONAL_SPREAD = 0.0055


def test_the_box_has_no_regional_bias_in_its_bounced_light(voxgi, tmp_path):
    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    follow_cycles(scene)
    ours = preview(tmp_path, scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT)
    with np.load(REFS / "cornell_box.npz") as data:
        reference = {key: data[key].astype(np.float64)[..., :3] for key in data.files}
    combined = reference["Combined"].sum(-1)
    off = ((ours["Diffuse Indirect"] - reference["Diffuse Indirect"]) *
           reference["Diffuse Color"]).sum(-1)
    h, w = combined.shape
    regions = np.array([[off[i * h // 6:(i + 1) * h // 6, j * w // 8:(j + 1) * w // 8].sum() /
                         combined[i * h // 6:(i + 1) * h // 6, j * w // 8:(j + 1) * w // 8].sum()
                         for j in range(8)] for i in range(6)])
    print(np.round(100 * regions, 1))
    assert abs(regions[1:5, 2:6].mean()) <= BACK_WALL_BIAS, np.round(100 * regions, 1)
    assert np.abs(regions).mean() <= REGIONAL_SPREAD, np.round(100 * regions, 1)


def cycles_total_12(scene, width, height, samples, diffuse_bounces, seed, denoise=False):
    """Cycles' passes with Total 12 (its default; ``cycles_passes`` sets Total to the larger of
    Diffuse and Glossy), ``diffuse_bounces`` and Glossy 4, AO distance 1 m."""
    from cycles_reference import _reference

    harness = _reference()
    settings = harness._render_settings

    def default_total(*args, **kwargs):
        return [(owner, name, 12 if name == "max_bounces" else value)
                for owner, name, value in settings(*args, **kwargs)]

    harness._render_settings = default_total
    try:
        return harness.render_cycles_passes(scene, width, height, samples,
                                            diffuse_bounces=diffuse_bounces, ao_distance=1.0,
                                            seed=seed, glossy_bounces=4, denoise=denoise)
    finally:
        harness._render_settings = settings


def quick_cycles(scene, width, height):
    """Cycles 16 spp + OpenImageDenoise (albedo and normal) at its default light paths (12
    total, 4 diffuse, 4 glossy bounces: the references'), seed 1: the quick preview artists
    already use."""
    passes = cycles_total_12(scene, width, height, 16, 4, seed=1, denoise=True)
    return {name: np.asarray(image, np.float64)[..., :3] for name, image in passes.items()}


@pytest.mark.parametrize("name", list(bounce_scenes.SCENES))
def test_default_preview_is_as_close_as_cycles_16_spp_with_oidn(voxgi, tmp_path, name):
    """The bar every preview is held to: at Cycles' default light paths the default preview's
    Combined lies at least as close to Cycles' converged render as Cycles' own 16 spp +
    OpenImageDenoise does, both measured here against the stored reference."""
    scene = bpy.context.scene
    bounce_scenes.build(name, scene)
    follow_cycles(scene)
    ours = preview(tmp_path, scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT)
    quick = quick_cycles(scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT)
    reference = np.load(REFS / f"{name}.npz")
    mask = reference["Alpha"] > 0.5
    truth = reference["Combined"].astype(np.float64)[..., :3]
    mine = relative_l1(ours["Combined"], truth, mask)
    theirs = relative_l1(quick["Combined"], truth, mask)
    print(name, f"preview {mine:.4f}", f"Cycles 16 spp + OIDN {theirs:.4f}")
    assert theirs > 0.005  # a real render, not the reference's own image
    assert mine <= theirs, (mine, theirs)


def test_thin_wall_dark_room_stays_dark(voxgi, tmp_path):
    """The room split by a 2 cm wall (thinner than the cache's 13 cm voxels): at the default
    Bounces the dark side's Diffuse Indirect stays ≤ 2% of the lit side's mean."""
    scene = bpy.context.scene
    scenes.build_thin_wall_room(scene)
    follow_cycles(scene)
    width, height = 128, 64
    ours = preview(tmp_path, scene, width, height)
    lit, dark = scenes.thin_wall_side_masks(width, height)
    indirect = ours["Diffuse Indirect"].mean(axis=-1)
    assert ours["Diffuse Direct"][dark].max() == 0.0
    lit_mean = indirect[lit].mean()
    assert lit_mean > 0.1
    ratio = indirect[dark].max() / lit_mean
    print(f"thin wall, 4 bounces: dark-side max / lit-side mean Diffuse Indirect = {ratio:.4f}")
    assert ratio <= 0.02


def cache_inputs():
    """(triangles, lights, Principled table, emission) of the context scene's snapshot: what
    the radiance cache is built from, on the GPU as in numpy."""
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.render import gpu_context
    from voxgi.voxgi_addon.gi.light_injection import material_emission
    from voxgi.voxgi_addon.gi.world_light import scene_lights
    from voxgi.voxgi_addon.preview.passes import principled_table
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    assert gpu_context.ensure_gpu_context()[0]
    snapshot, _ = snapshot_or_error(bpy.context, bpy.context.evaluated_depsgraph_get())
    tris = world_triangles(snapshot)
    emission = material_emission(snapshot)
    return tris, scene_lights(snapshot, tris, emission), principled_table(snapshot), emission


def gpu_and_numpy_caches(bounces: int = 3, rays: int = 8, resolution: int = 16):
    """The context scene's radiance cache of ``bounces`` built on the GPU and in numpy, with
    (triangles, lights, Principled table, emission) (``cache_inputs``)."""
    from voxgi.render import gpu_gather
    from voxgi.render.gpu_bvh import shared_bvh
    from voxgi.voxgi_addon.gi import radiance_cache
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    inputs = tris, lights, principled, emission = cache_inputs()
    settings = GatherSettings(bounces=bounces, cache_resolution=resolution, cache_rays=rays)
    gpu, _ = gpu_gather.cache_gpu(shared_bvh().update(tris), lights, principled, emission,
                                  settings)
    numpy = radiance_cache.cached_cache(tris, lights, principled, emission, bounces, rays,
                                        resolution)
    return gpu, numpy, inputs


def test_gpu_cache_equals_numpy_cache(voxgi):
    """Two iterations (Bounces 3) of the cache on the Cornell box, one grid and Auto's grids
    nested around a camera: the GPU's voxel faces equal numpy's within 2%, and so do the
    third iteration, from which the faces' one-more-bounce ratio comes
    (``radiance_cache.one_more_bounce``)."""
    from voxgi.render import gpu_gather
    from voxgi.render.gpu_bvh import shared_bvh
    from voxgi.voxgi_addon.gi import radiance_cache
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    bounce_scenes.build("cornell_box", bpy.context.scene)
    gpu, numpy, (tris, lights, principled, emission) = gpu_and_numpy_caches()
    settings = GatherSettings(bounces=3, cache_resolution=16, cache_rays=8)
    assert gpu.iterations == numpy.iterations == 2
    a, b = (np.concatenate(c.faces).astype(np.float64) for c in (gpu, numpy))
    assert b.mean() > 0.01
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.02
    a, b = (np.concatenate(c.ahead).astype(np.float64) for c in (gpu, numpy))
    assert b.mean() > np.concatenate(numpy.faces).mean() > 0.01  # one bounce more
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.02
    # Auto's grids nested around a focus inside the box (the finest grid that holds a point
    # is read), within the emitters' focus' budget: the GPU's faces and lookups
    # (cache_lookup.glsl) still equal numpy's
    inside = radiance_cache.snap_focus(tris, (0.0, 0.0, 1.0))
    budget = radiance_cache.RAYS_PER_ITERATION
    nested = GatherSettings(bounces=3, cache_rays=16, cache_focus=inside, cache_nest_rays=budget)
    gpu_nested, _ = gpu_gather.cache_gpu(shared_bvh().update(tris), lights, principled, emission,
                                         nested)
    numpy_nested = radiance_cache.cached_cache(tris, lights, principled, emission, 3, 16, 0,
                                               focus=inside, nest_rays=budget)
    assert len(gpu_nested.grids) == len(numpy_nested.grids) > 1
    a, b = (np.concatenate(c.faces).astype(np.float64) for c in (gpu_nested, numpy_nested))
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.02
    # the same triangles snapshotted again (a viewport slice) keep the uploaded cache
    texture = gpu_gather.cache_texture(shared_bvh(), lights, principled, emission, settings)
    again, again_lights, _, _ = cache_inputs()
    assert again is not tris
    assert gpu_gather.cache_texture(shared_bvh().update(again), again_lights, principled,
                                    emission, settings) is texture


def test_gpu_cache_equals_numpy_cache_where_faces_lie_behind_the_point(voxgi, monkeypatch):
    """The emissive room's panel 5 cm under its ceiling (Bounces 3, 64³): its lookups and
    picks leave out the faces behind the point's tangent plane (``radiance_cache._in_front``,
    cache_lookup.glsl ``cache_in_front``, the planes packed in the id texels). The GPU's faces
    equal numpy's within 0.2% (measured 0.02%), while numpy without the plane test lies 0.6%
    from them: a GPU that left the test out would fail."""
    from voxgi.voxgi_addon.gi import radiance_cache

    bounce_scenes.build("emissive_room", bpy.context.scene)
    gpu, numpy, (tris, lights, principled, emission) = gpu_and_numpy_caches(resolution=64)
    a, b = (np.concatenate(c.faces).astype(np.float64) for c in (gpu, numpy))
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.002
    monkeypatch.setattr(radiance_cache, "PLANE_TOLERANCE", np.inf)
    radiance_cache._MEMO.clear()
    without = radiance_cache.cached_cache(tris, lights, principled, emission, 3, 8, 64)
    radiance_cache._MEMO.clear()
    c = np.concatenate(without.faces).astype(np.float64)
    assert np.abs(c - b).sum() / np.abs(b).sum() >= 0.003


def test_f12_lays_the_cache_out_on_a_thread_while_the_bvh_builds_and_once(voxgi, tmp_path,
                                                                            monkeypatch):
    """F12's first preview of a scene starts the radiance cache's layout (its voxels and face
    points, numpy) on a thread of its own as soon as the triangles are known, while the main
    thread builds the BVH; the cache's stage then takes that layout: it is made once, on that
    thread, and the preview is the one a layout made in the stage gives."""
    import threading

    from voxgi.render import gpu_gather, gpu_preview, gpu_scene

    bounce_scenes.build("cornell_box", bpy.context.scene)
    scene = bpy.context.scene
    follow_cycles(scene)
    made = []
    build_cache = gpu_gather.build_cache

    def counted(*args, **kwargs):
        made.append(threading.current_thread().name)
        return build_cache(*args, **kwargs)

    monkeypatch.setattr(gpu_gather, "build_cache", counted)
    gpu_scene.release()
    gpu_gather._LAYOUT.clear()
    ahead = preview(tmp_path, scene, 64, 48)
    assert made == ["VoxGI cache layout"], made
    assert not gpu_gather._AHEAD  # taken by the cache's stage
    # without the layout made ahead: the same image
    monkeypatch.setattr(gpu_preview, "cache_layout_ahead", lambda tris, settings: None)
    gpu_scene.release()
    gpu_gather._LAYOUT.clear()
    gpu_gather.drop_shared_cache()
    (tmp_path / "inline").mkdir()
    inline = preview(tmp_path / "inline", scene, 64, 48)
    assert made[1:] == ["MainThread"], made
    np.testing.assert_allclose(ahead["Combined"], inline["Combined"], rtol=1e-5, atol=1e-6)


def test_a_layout_that_fails_ahead_raises_its_error_where_the_cache_asks_for_it(voxgi,
                                                                               monkeypatch):
    """A layout made ahead that fails (a bad mesh, memory) is not lost on its thread: the
    cache's own ``cache_layout`` raises that error, once, and does not lay out again."""
    from voxgi.render import gpu_gather
    from voxgi.voxgi_addon.preview.gather import GatherSettings

    bounce_scenes.build("cornell_box", bpy.context.scene)
    tris = cache_inputs()[0]
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        raise MemoryError("the cache's voxels do not fit")

    monkeypatch.setattr(gpu_gather, "build_cache", failing)
    gpu_gather._LAYOUT.clear()
    settings = GatherSettings(bounces=3, cache_resolution=16, cache_rays=8)
    gpu_gather.cache_layout_ahead(tris, settings)
    with pytest.raises(MemoryError, match="do not fit"):
        gpu_gather.cache_layout(tris, settings)
    assert calls == [1] and not gpu_gather._AHEAD


@pytest.mark.parametrize("sparse, diffuse_one", [(False, False), (True, False), (True, True)],
                         ids=["dense", "sparse", "cycles-diffuse-1"])
def test_numpy_and_gpu_previews_agree(voxgi, tmp_path, sparse, diffuse_one):
    """Bounces 2 on a small Cornell box image: every pass of the GPU preview (the cache's
    lookups in bvh_shade.glsl) within 2% of numpy's — also with Sparse Gathers
    (``preview.sparse_gather``: the GPU's list of gather points and its hole-filling filter
    against numpy's), and at Cycles' Diffuse 1 with its glossy bounces (one bounce reading
    the cache's first iteration ahead by the glossy shares: "One bounce and Cycles' glossy
    bounces")."""
    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    scene.voxgi.bounces = 2
    if diffuse_one:
        scene.voxgi.bounce_source = "CYCLES"
        scene.cycles.diffuse_bounces = 1
    scene.voxgi.sparse_gathers = sparse
    gpu = preview(tmp_path, scene, 48, 36, "AUTO")
    reference = preview(tmp_path, scene, 48, 36, "NUMPY")
    everywhere = np.ones((36, 48), bool)
    assert reference["Diffuse Indirect"].mean() > 0.01
    for name in PASSES:
        assert relative_l1(gpu[name], reference[name], everywhere) <= 0.02, name


def test_one_bounce_keeps_cycles_glossy_bounces(voxgi):
    """Cycles' Diffuse 1 with its other Light Paths at their defaults (Glossy 4, Total 12):
    a path's glossy scatters go on past its one diffuse bounce, and a diffuse bounce goes on
    past the receiver's glossy one. The Cornell box's preview sums within 1.5% of Cycles'
    Combined, 3% of its Diffuse Indirect and 8% of its Glossy Indirect (1.000, 1.002, 0.985
    at 160 × 120, 1,024 rays, no filter; without the diffuse gather's glossy picks 0.986,
    0.949, 0.985; without the glossy chains 0.949, 0.911, 0.731: docs/gi_pipeline.md "One
    bounce and Cycles' glossy bounces", "The diffuse gather's glossy picks")."""
    from voxgi.blender.settings import glossy_chains
    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    width, height = 80, 60
    cycles = cycles_total_12(scene, width, height, 512, 1, seed=3)
    scene.voxgi.bounce_source = "CYCLES"
    scene.cycles.diffuse_bounces, scene.cycles.glossy_bounces = 1, 4
    scene.cycles.max_bounces = 12
    assert glossy_chains(scene.voxgi)
    passes, _ = render_scene_passes(bpy.context, scene, None, width, height)
    ours = {k: np.asarray(v, np.float64) for k, v in passes.items() if hasattr(v, "shape")}
    mask = np.asarray(cycles["Alpha"]) > 0.5
    if mask.ndim == 3:
        mask = mask[..., 0]
    sums = image_sums(ours, mask)
    theirs = image_sums({k: np.asarray(v, np.float64) for k, v in cycles.items()}, mask)
    combined = ours["Combined"][..., :3][mask].sum() / \
        np.asarray(cycles["Combined"])[..., :3][mask].sum()
    print("Combined", combined, {k: sums[k] / theirs[k] for k in sums})
    assert abs(combined - 1.0) <= 0.015, combined
    assert abs(sums["Diffuse"] / theirs["Diffuse"] - 1.0) <= 0.03, (sums, theirs)
    assert abs(sums["Glossy"] / theirs["Glossy"] - 1.0) <= 0.08, (sums, theirs)
    scene.cycles.max_bounces = 1  # a Total of 1 ends every path at its first bounce
    assert not glossy_chains(scene.voxgi)
    scene.cycles.max_bounces, scene.cycles.diffuse_bounces = 12, 0  # no diffuse bounce at all
    assert not glossy_chains(scene.voxgi)


def metal_room():
    import light_scenes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    light_scenes.build("metal_room", scene)
    follow_cycles(scene)
    return scene


def image_sums(passes, mask):
    """Diffuse and Glossy Indirect × their colours, summed over ``mask``: the light the
    later bounces bring."""
    return {kind: float((np.asarray(passes[f"{kind} Indirect"])[..., :3] *
                         np.asarray(passes[f"{kind} Color"])[..., :3])[mask].sum())
            for kind in ("Diffuse", "Glossy")}


def test_metals_reflect_the_later_bounces_where_they_point(voxgi):
    """The metal room (steel floor, copper wall, gold sphere) at the default Bounces against
    Cycles at its default light paths (256 spp, both summed over the image): the indirect light
    the metals bring is within 5% of Cycles' (Diffuse Indirect) and 3% (Glossy Indirect):
    1.027 and 0.998 at 80 × 60. A metal's lobe that took the cache's light as arriving evenly
    from every direction brought 12% and 8% too much here: its reflection at grazing angles sees the open room's black
    world, not the lit walls the cache averages (docs/gi_pipeline.md "Metals reflect where
    they point")."""
    from cycles_reference import render_cycles_passes

    from voxgi.render.pipeline import render_scene_passes

    width, height = 80, 60
    ours, _ = render_scene_passes(bpy.context, metal_room(), None, width, height)
    cycles = render_cycles_passes(metal_room(), width, height, 256, diffuse_bounces=4,
                                  glossy_bounces=4)
    mask = cycles["Alpha"] > 0.5
    mine, theirs = image_sums(ours, mask), image_sums(cycles, mask)
    ratios = {kind: mine[kind] / theirs[kind] for kind in mine}
    print({kind: round(r, 4) for kind, r in ratios.items()})
    assert abs(ratios["Diffuse"] - 1.0) <= 0.05, ratios
    assert abs(ratios["Glossy"] - 1.0) <= 0.03, ratios


def test_gpu_cache_follows_the_metals_as_numpy_does(voxgi):
    """The cache's own rays that land on a metal are followed one reflection further too, each
    record reading one face of the two hits by their weights (cache_paths.glsl,
    ``radiance_cache.follow_metals``): on the metal room (Bounces 3), the GPU's voxel faces
    equal numpy's within 2%, and they differ from the faces of a cache that takes the metals'
    lobes as reading uniform light."""
    from voxgi.voxgi_addon.gi import radiance_cache
    from voxgi.voxgi_addon.gi.exact_indirect import gather_rays, ray_paths

    metal_room()
    gpu, numpy, (tris, lights, principled, emission) = gpu_and_numpy_caches()
    a, b = (np.concatenate(c.faces).astype(np.float64) for c in (gpu, numpy))
    assert b.mean() > 0.01
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.02
    # the first iteration of the same layout from its rays followed or not: the metals'
    # second hits bring light the plain rays' lookups would have taken as uniform
    cache = radiance_cache.build_cache(tris, 16, rays=8)
    points, axes = radiance_cache.face_points(cache)
    origins, dirs, ids = gather_rays(points, axes, np.arange(len(points)), 8, 0)
    plain = ray_paths(origins, dirs, ids, tris, lights, principled, emission, 0,
                      (0.0, 0.0, 0.0), 1, True)
    followed = radiance_cache.face_paths(cache, tris, lights, principled, emission, 8)
    a, b = (np.concatenate(radiance_cache.relax(cache, p, 8).faces).astype(np.float64)
            for p in (followed, plain))
    assert np.abs(a - b).sum() / np.abs(b).sum() > 0.05


def test_numpy_and_gpu_follow_the_metals_alike(voxgi):
    """Bounces 2 on the metal room (every gather point traced): the metal hits' reflections
    followed one bounce further (bvh_shade.glsl ``metal_lobe_ray``, exact_indirect
    ``metal_lobe_rays``) draw the same directions and light samples on the GPU as in numpy —
    every pass within 2%."""
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    passes = {}
    for tracer in ("AUTO", "NUMPY"):
        scene = metal_room()
        scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 2
        scene.voxgi.sparse_gathers = False
        scene.voxgi.tracer = tracer
        out, _ = render_scene_passes(bpy.context, scene, None, 48, 36)
        assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy")
        passes[tracer] = {k: np.array(v, np.float64) for k, v in out.items()}
    everywhere = np.ones((36, 48), bool)
    assert passes["NUMPY"]["Glossy Indirect"].mean() > 0.01
    for name in PASSES:
        assert relative_l1(passes["AUTO"][name], passes["NUMPY"][name], everywhere) <= 0.02, name


class _Layout:
    """Records the properties a panel draws; every container call returns itself."""

    def __init__(self):
        self.props = []

    def box(self, **_kwargs):
        return self

    row = column = split = box

    def label(self, *_args, **_kwargs):
        pass

    operator = label

    def prop(self, _data, name, **_kwargs):
        self.props.append(name)


def test_bounces_setting_follows_cycles_and_is_drawn(voxgi):
    """Follow Cycles reads the scene's Light Paths (Diffuse capped by Total, at least 1);
    Manual its own count; both panels draw the setting in both qualities (Fast's voxels reflect
    the cache too, gi/cone_bounces.py)."""
    from voxgi.blender.settings import diffuse_bounces

    scene = bpy.context.scene
    settings = scene.voxgi
    settings.bounce_source = "CYCLES"
    scene.cycles.diffuse_bounces, scene.cycles.max_bounces = 6, 3
    assert diffuse_bounces(settings) == 3
    scene.cycles.diffuse_bounces, scene.cycles.max_bounces = 0, 12
    assert diffuse_bounces(settings) == 1
    settings.bounce_source, settings.bounces = "MANUAL", 7
    assert diffuse_bounces(settings) == 7
    for quality, shown in (("ACCURATE", True), ("FAST", True)):
        settings.quality = quality
        layout = _Layout()
        bpy.types.VOXGI_PT_gi.draw(type("PanelStub", (), {"layout": layout})(), bpy.context)
        assert ({"bounce_source", "bounces"} <= set(layout.props)) == shown, layout.props
    from voxgi.ui.render_properties import CONE_SETTINGS
    assert {"bounce_source", "bounces"} <= set(CONE_SETTINGS)


def gold_ball_in_the_sun():
    """Three smooth gold balls on a grey floor by a wall, under a small bright sun and a dim
    sky: the floor's cache rays that land on a ball's spot mirroring the sun meet a caustic."""
    import math

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("sky")
    scene.world = world
    world.color = (0.1, 0.12, 0.16)

    def material(name, colour, metallic=0.0, roughness=0.5):
        made = bpy.data.materials.new(name)
        made.diffuse_color = (*colour, 1.0)
        made.metallic, made.roughness = metallic, roughness
        made.use_nodes = True
        bsdf = made.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
        bsdf.inputs["Metallic"].default_value = metallic
        bsdf.inputs["Roughness"].default_value = roughness
        return made

    bpy.ops.mesh.primitive_plane_add(size=6)
    bpy.context.object.data.materials.append(material("floor", (0.6, 0.6, 0.6)))
    bpy.ops.mesh.primitive_cube_add(location=(0.0, 1.6, 0.8), scale=(2.5, 0.1, 0.8))
    bpy.context.object.data.materials.append(material("wall", (0.6, 0.55, 0.5)))
    gold = material("gold", (1.0, 0.77, 0.34), 1.0, 0.2)
    for x in (-1.2, 0.0, 1.2):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(x, 0.3, 0.4), segments=48,
                                             ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(gold)
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(50), 0.0, math.radians(20)))
    bpy.context.object.data.energy = 5.0
    bpy.context.object.data.angle = math.radians(0.5)
    return scene


def test_a_caustic_met_by_one_cache_ray_lights_no_voxel(voxgi):
    """One ray of a voxel face's eight that lands on the spot of a gold ball that mirrors the
    sun toward the face carries that caustic alone (hundreds of times the others' light); the
    face's mean then lit the whole voxel, and a metal that reflected the floor showed a blob 4×
    Cycles' brightness where Cycles draws a few fireflies (docs/gi_pipeline.md "A caustic in the
    cache's rays"). Such a lone ray off a metal is tamed to ``OUTLIER_FLOOR`` (or 4× the face's
    next brightest ray): on the gold balls' scene some faces' rays are, the GPU's faces equal
    numpy's within 2%, and those faces' own light is at most half what the lone ray gave them."""
    from voxgi.voxgi_addon.gi import radiance_cache

    gold_ball_in_the_sun()
    gpu, numpy, (tris, lights, principled, emission) = gpu_and_numpy_caches(bounces=2,
                                                                           resolution=32)
    a, b = (np.concatenate(c.faces).astype(np.float64) for c in (gpu, numpy))
    assert np.abs(a - b).sum() / np.abs(b).sum() <= 0.02
    layout = radiance_cache.build_cache(tris, 32, rays=8)
    paths = radiance_cache.face_paths(layout, tris, lights, principled, emission, 8)
    raw = np.asarray(paths.radiance, np.float64)
    tamed = radiance_cache.tamed(raw, 8, radiance_cache.metal_hits(paths))
    changed = np.flatnonzero(np.abs(tamed - raw).max(axis=1) > 0)
    print("tamed rays", len(changed))
    assert len(changed) >= 1, "no cache ray met the ball's caustic: the scene tests nothing"
    peaks = raw.max(axis=1).reshape(-1, 8)
    faces = changed // 8
    # each tamed ray was a lone outlier: over 4× its face's next brightest and over the floor
    ordered = np.sort(peaks[faces], axis=1)
    assert (ordered[:, -1] > 4.0 * ordered[:, -2]).all()
    assert (ordered[:, -1] > radiance_cache.OUTLIER_FLOOR).all()
    # those faces' own light fell from the lone ray's share to the rest's: what lit a voxel
    before = raw.reshape(-1, 8, 3)[faces].mean(axis=1).max(axis=1)
    after = tamed.reshape(-1, 8, 3)[faces].mean(axis=1).max(axis=1)
    assert (before > after).all() and (before >= 1.5 * after).any(), (before, after)


def test_a_sphere_without_specular_beside_another_keeps_the_bounced_light_bounded(voxgi,
                                                                                 tmp_path):
    """A Principled BSDF at Specular IOR Level 0 (no reflection at all: FBX imports bring such
    materials) beside another sphere: some cache faces were lit at 1e-17 of the others and held
    a one-more-bounce ratio of 1e16, which the lookup blended with their bright neighbours'
    light unweighted — Diffuse Indirect reached 1e3 (GPU) and 1e13 (numpy) where Cycles reads
    under 2. Each face's ratio now counts by its light (``radiance_cache.lookup``)."""
    scene = bpy.context.scene
    floor = scenes.principled("Floor", (0.8, 0.8, 0.8))
    scenes.mesh_object("Floor", [(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)],
                       [(0, 1, 2, 3)]).data.materials.append(floor)
    chalk = scenes.principled("Chalk", (0.2, 0.6, 0.2), roughness=1.0, specular=0.0)
    blue = scenes.principled("Blue", (0.1, 0.4, 0.8))
    for k, material in enumerate((blue, chalk)):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=(1.5 * k, 0.5, 0.6))
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(material)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "AREA"))
    lamp.data.energy, lamp.data.size, lamp.location = 300.0, 1.0, (1.0, -1.0, 3.0)
    scene.collection.objects.link(lamp)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location, camera.rotation_euler = (0.75, -4.5, 1.4), (1.396, 0.0, 0.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    world = bpy.data.worlds.new("Sky")
    world.color = (0.3, 0.35, 0.45)
    scene.world = world
    follow_cycles(scene)
    for tracer, size in (("AUTO", (80, 60)), ("NUMPY", (40, 30))):
        ours = preview(tmp_path, scene, *size, tracer=tracer)
        assert np.isfinite(ours["Combined"]).all()
        assert ours["Diffuse Indirect"].max() < 3.0, (tracer, ours["Diffuse Indirect"].max())
        assert ours["Combined"].max() < 10.0, (tracer, ours["Combined"].max())

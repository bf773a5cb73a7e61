"""Exact ray casting on the GPU (render/gpu_bvh.py, shaders/bvh_*.glsl) against the numpy
references: raycast.py's hits, the hashed sample patterns, direct_light.diffuse_direct and
indirect.indirect_and_ao; and the preview's direct light with shadows "RAYS" on the GPU."""

import bpy
import numpy as np
import pytest
import scenes


def relative_l1(ours, reference):
    return float(np.abs(ours - reference).sum() / max(np.abs(reference).sum(), 1e-12))


def gpu_ready():
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    assert ready, f"no GPU context in background mode: {why}"


def snapshot_now():
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    snapshot = take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
    return snapshot, world_triangles(snapshot)


def demo_scene():
    from voxgi.blender.demo_scene import build_demo_scene

    build_demo_scene(bpy.context.scene)
    return snapshot_now()


def add_lights(scene):
    """A sun, a spot and a disk area light besides the Cornell box's own light."""
    sun = scenes._light(scene, "Test Sun", "SUN", (0.0, 0.0, 5.0), energy=2.0, angle=0.1)
    sun.rotation_euler = (0.5, 0.3, 0.0)  # through the open front, at a slant
    spot = scenes._light(scene, "Test Spot", "SPOT", (0.6, -0.5, 1.8), energy=60.0,
                         spot_size=1.2, spot_blend=0.3, shadow_soft_size=0.1)
    spot.rotation_euler = (0.3, 0.2, 0.0)
    disk = scenes._light(scene, "Test Disk", "AREA", (-0.5, 0.6, 1.9), energy=40.0, size=0.3,
                         shape="DISK")
    disk.rotation_euler = (0.2, 0.0, 0.0)
    point = scenes._light(scene, "Test Point 2", "POINT", (0.5, 0.5, 1.0), energy=30.0,
                          shadow_soft_size=0.0)
    point.data.color = (1.0, 0.6, 0.3)


def test_gpu_hits_equal_the_grid_ray_caster_on_the_demo_scene(voxgi):
    from voxgi.render.gpu_bvh import GPUBVH, trace_rays
    from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded

    _, tris = demo_scene()
    gpu_ready()
    bvh = GPUBVH().update(tris)
    assert bvh.uploaded_bytes > 0
    rng = np.random.default_rng(7)
    n = 4000
    lo, hi = tris.bounds
    o = rng.uniform(lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo), (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, tri, u, v = trace_rays(bvh, o, d, 1e-4, np.inf)
    rt, rtri, ru, rv = closest_hits(tris, o, d, 1e-4)
    assert np.isfinite(rt).mean() > 0.5
    same = tri == rtri
    assert same.mean() > 0.995, same.mean()  # float32 vs float64 at shared edges
    hit = same & (rtri >= 0)
    np.testing.assert_allclose(t[hit], rt[hit], rtol=1e-4, atol=1e-5)
    assert np.abs(u[hit] - ru[hit]).max() < 1e-3 and np.abs(v[hit] - rv[hit]).max() < 1e-3
    max_t = rng.uniform(0.05, 3.0, n)
    blocked = trace_rays(bvh, o, d, 0.0, max_t, any_hit=True)
    assert (blocked == occluded(tris, o, d, max_t)).mean() > 0.995
    # Unchanged triangles (a new SceneTriangles with the same corners) upload nothing.
    _, again = snapshot_now()
    bvh.update(again)
    assert bvh.uploaded_bytes == 0


def test_gpu_hits_are_the_same_in_one_layout_or_one_per_ray_direction(voxgi, monkeypatch):
    """A BVH whose nodes pass ``ORDERED_BYTES`` is packed in one layout (bvh.node_layouts): the
    GPU's traversal tells it by the texture's height and finds the hits it finds in the six
    (each layout more rows than there are layouts: an 80k-triangle sphere in the demo scene)."""
    from voxgi.render.gpu_bvh import GPUBVH, trace_rays
    from voxgi.voxgi_addon.scene import bvh as bvh_module

    demo_scene()
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=6, radius=0.4, location=(0.0, 0.0, 1.0))
    _, tris = snapshot_now()
    gpu_ready()
    rng = np.random.default_rng(3)
    lo, hi = tris.bounds
    o = rng.uniform(lo, hi, (3000, 3))
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    max_t = rng.uniform(0.05, 3.0, len(o))
    six = GPUBVH().update(tris)
    assert six.nodes.height % bvh_module.ORDERS == 0 and six.nodes.height >= bvh_module.ORDERS ** 2
    ordered = trace_rays(six, o, d, 1e-4, np.inf), trace_rays(six, o, d, 0.0, max_t, any_hit=True)
    monkeypatch.setattr(bvh_module, "ORDERED_BYTES", 0)
    one = GPUBVH().update(tris)
    assert one.nodes.height % bvh_module.ORDERS == 1
    single = trace_rays(one, o, d, 1e-4, np.inf), trace_rays(one, o, d, 0.0, max_t, any_hit=True)
    assert np.isfinite(single[0][0]).mean() > 0.5 and single[1].mean() > 0.1
    assert (single[0][1] == ordered[0][1]).mean() > 0.999  # (ties between coplanar triangles)
    assert (single[1] == ordered[1]).mean() > 0.999


def test_sample_patterns_are_bit_exact(voxgi):
    from voxgi.render.gpu_bvh import sample_patterns
    from voxgi.voxgi_addon.gi.sampling import (
        hammersley,
        hashed_square,
        pcg_hash,
        unit_float,
    )

    gpu_ready()
    w, h = 64, 32
    got = sample_patterns(w, h)
    k = np.arange(w * h, dtype=np.uint32)
    np.testing.assert_array_equal(got[:, 0], unit_float(pcg_hash(k)).astype(np.float32))
    np.testing.assert_array_equal(got[:, 1:3], hashed_square(k, 3, 16)[:, 5].astype(np.float32))
    np.testing.assert_allclose(got[:, 3], hammersley(k, 0, 8)[:, 3, 0], atol=1e-6)


def gpu_direct_and_reference(samples=16):
    """(GPU Diffuse Direct, numpy diffuse_direct on the same G-buffer points with the same
    sample ids, hit mask) of the current scene at 96 × 72, top row first."""
    from voxgi.render.gbuffer import rasterize, read_gbuffer
    from voxgi.render.gpu_bvh import GPUBVH, direct_light_texture
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
    from voxgi.voxgi_addon.preview.passes import SURFACE_EPSILON, material_table

    snapshot, tris = snapshot_now()
    gpu_ready()
    w, h = 96, 72
    _, rough, _, _ = material_table(snapshot)
    gbuffer = rasterize(tris, snapshot.camera, rough, w, h)
    seen = read_gbuffer(gbuffer)
    bvh = GPUBVH().update(tris)
    gpu = np.flipud(read_texture(direct_light_texture(bvh, gbuffer.inputs, snapshot.lights,
                                                      samples)))[..., :3]
    hit = seen["hit"]
    ids = np.flatnonzero(hit.ravel())
    p = seen["position"][hit].astype(np.float64)
    n = seen["normal"][hit].astype(np.float64)
    ref = np.zeros((h, w, 3), np.float32)
    ref[hit] = diffuse_direct(p + n * SURFACE_EPSILON, n, snapshot.lights, tris, samples=samples,
                              sample_ids=ids)
    return gpu, ref, hit, snapshot


@pytest.mark.parametrize("light", ["AREA", "POINT", "ALL"])
def test_gpu_direct_light_equals_numpy(voxgi, light):
    scene = bpy.context.scene
    scenes.build_test_cornell_box(scene, light="POINT" if light == "POINT" else "AREA")
    if light == "ALL":
        add_lights(scene)
    gpu, ref, hit, snapshot = gpu_direct_and_reference()
    if light == "ALL":
        assert {lamp.type for lamp in snapshot.lights} == {"SUN", "SPOT", "AREA", "POINT"}
    error = relative_l1(gpu[hit], ref[hit])
    print(f"{light}: GPU vs numpy Diffuse Direct relative L1 {error:.5f}")
    assert error < 0.01
    assert ref[hit].mean() > 0.05
    # Shadows are there: some lit pixels are much darker than the median.
    value = ref[hit].sum(-1)
    assert (value < 0.2 * np.median(value)).mean() > 0.02



def test_gpu_direct_light_traces_nothing_where_no_diffuse_colour_shows(voxgi):
    """Given the texels' Diffuse Color (the sub-pixel passes' world and emitters dispatch), a
    texel whose colour is 0 (a full metal: its Diffuse Direct is only read times it) reads 0
    and the others read exactly what the dispatch without it gives."""
    from voxgi.render.gbuffer import rasterize
    from voxgi.render.gpu_bvh import GPUBVH, direct_light_texture
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.passes import material_table

    scenes.build_test_cornell_box(bpy.context.scene, light="AREA")
    snapshot, tris = snapshot_now()
    gpu_ready()
    w, h = 96, 72
    gbuffer = rasterize(tris, snapshot.camera, material_table(snapshot)[1], w, h)
    bvh = GPUBVH().update(tris)
    colour = np.full((h, w, 4), 0.5, np.float32)
    colour[:, : w // 2, :3] = 0.0  # the left half (in the texture's rows) shows no diffuse light
    lit = read_texture(direct_light_texture(bvh, gbuffer.inputs, snapshot.lights, 16))
    masked = read_texture(direct_light_texture(bvh, gbuffer.inputs, snapshot.lights, 16,
                                               colour=float_texture(colour, (w, h))))
    assert lit[:, : w // 2, :3].mean() > 0.05  # there is light there to leave out
    assert not masked[:, : w // 2].any()
    np.testing.assert_array_equal(masked[:, w // 2:], lit[:, w // 2:])

def soft_hdri_world():
    """The synthetic HDRI of light_scenes with its sun's disc held at 40: the map's importance
    still leans on it (the map's rays are the bounce hits' half), but no ray of the few a
    point traces here is worth the whole image's difference — at 30,000 one shadow ray that
    float32 and float64 draw a hair apart at the disc's edge moved a pixel by 16 (84% of the
    difference in 10 pixels)."""
    import light_scenes

    pixels = light_scenes.hdri_pixels(256, 128)
    pixels[..., :3] = np.minimum(pixels[..., :3], 4.0)
    image = bpy.data.images.new("Soft HDRI", 256, 128, float_buffer=True)
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    world = light_scenes.hdri_world("Soft HDRI World")
    next(n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT").image = image
    # ten times as strong: a good share of the box's bounce light, the sun's disc at 40
    next(n for n in world.node_tree.nodes if n.type == "BACKGROUND").inputs[
        "Strength"].default_value = 10.0
    return world


@pytest.mark.parametrize("lamps", ["AREA", "AREA+POINT", "AREA+SPOT", "AREA+HDRI"])
def test_gpu_ao_and_indirect_equal_numpy(voxgi, lamps):
    """The raw gather (shaders/bvh_gather.glsl, every pixel, before filtering): AO, Diffuse
    Indirect and both variances equal gi.exact_indirect's on the same rays — with two lamps,
    each bounce hit tracing the one both pick (exact_indirect.lamp_picks); under an HDRI, each
    hit's world stratum drawing the same one ray (world_light.one_technique)."""
    from voxgi.render.gbuffer import rasterize, read_gbuffer
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_gather import gather
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.voxgi_addon.gi.exact_indirect import indirect_and_ao
    from voxgi.voxgi_addon.gi.world_light import scene_lights
    from voxgi.voxgi_addon.preview.gather import GatherSettings
    from voxgi.voxgi_addon.preview.passes import material_table, principled_table

    scene = bpy.context.scene
    scenes.build_test_cornell_box(scene, light="AREA")
    if lamps == "AREA+POINT":
        location, settings = scenes.TEST_BOX_LIGHTS["POINT"]
        scenes._light(scene, "Test Point Light", "POINT", location, **settings)
    if lamps == "AREA+SPOT":  # shining down on the short block's side of the floor
        scenes._light(scene, "Test Spot Light", "SPOT", (0.4, -0.2, 1.6), energy=150.0,
                      spot_size=0.9, spot_blend=0.3, shadow_soft_size=0.05)
    if lamps == "AREA+HDRI":  # its sky through the box's open side
        scene.world = soft_hdri_world()
    snapshot, tris = snapshot_now()
    gpu_ready()
    w, h, rays = 40, 30, 8
    _, rough, _, emission = material_table(snapshot)
    principled = principled_table(snapshot)
    gbuffer = rasterize(tris, snapshot.camera, rough, w, h)
    seen = read_gbuffer(gbuffer)
    settings = GatherSettings(rays=rays, ao_distance=1.0, seed=3)
    lights = scene_lights(snapshot, tris, emission)  # the lamps, and the world when it shines
    values, variance, _ = gather(GPUBVH().update(tris), gbuffer.inputs, lights, principled,
                                 emission, settings, 1, w, h)
    out, out_var = np.flipud(read_texture(values)), np.flipud(read_texture(variance))
    hit = seen["hit"]
    ids = np.flatnonzero(hit.ravel())
    indirect, ao, var = indirect_and_ao(seen["position"][hit], seen["normal"][hit], ids, tris,
                                        lights, principled, emission, rays=rays,
                                        ao_distance=1.0, seed=3, statistics=True,
                                        hit_glossy=settings.hit_glossy)
    ao_error = relative_l1(out[hit][:, 3], ao)
    indirect_error = relative_l1(out[hit][:, :3], indirect)
    variance_error = relative_l1(out_var[hit][:, :2], var[:, :2])
    # the points' reach, the harmonic mean of their rays' hit distances (−.z on the GPU)
    reach_error = relative_l1(-out_var[hit][:, 2], var[:, 2])
    print(f"GPU vs numpy: AO {ao_error:.5f}, Diffuse Indirect {indirect_error:.5f}, "
          f"variances {variance_error:.5f}, reaches {reach_error:.5f}")
    assert ao_error < 0.02 and indirect_error < 0.02 and variance_error < 0.02
    assert reach_error < 0.02 and 0.05 < np.median(var[:, 2]) < 2.0
    assert 0.2 < ao.mean() < 0.95 and indirect.mean() > 0.01
    if lamps == "AREA+HDRI":  # the world lights the hits: the test sees its rays
        lamps_only = indirect_and_ao(seen["position"][hit], seen["normal"][hit], ids, tris,
                                     [light for light in lights if light.type != "WORLD"],
                                     principled, emission, rays=rays, ao_distance=1.0, seed=3,
                                     hit_glossy=settings.hit_glossy)[0]
        print(f"the world's share of the indirect light: {1 - lamps_only.mean() / indirect.mean():.3f}")
        assert lamps_only.mean() < 0.9 * indirect.mean()
    # Red and green walls bleed: the indirect light is not grey everywhere.
    assert np.abs(indirect[:, 0] - indirect[:, 1]).max() > 0.02


@pytest.mark.parametrize("lamps", ["one", "five"])
def test_preview_direct_light_runs_on_the_gpu(voxgi, lamps):
    """shadows = RAYS: the GPU preview's Diffuse Direct equals the numpy preview's, with the
    box's one lamp and with five of every kind (each lamp's dispatch reads its own row of the
    lights: a wrong row would light the box with another lamp's colour and place); with five,
    its Glossy Direct too."""
    from test_gpu_tracer import cornell, cornell_state

    from voxgi.blender.settings import cone_settings
    from voxgi.render.gpu_bvh import shared_bvh
    from voxgi.render.gpu_preview import render_passes_gpu
    from voxgi.voxgi_addon.preview.passes import render_passes

    scene = cornell("AREA")
    if lamps == "five":
        add_lights(scene)
    snapshot, state = cornell_state(scene)
    gpu_ready()
    cones = cone_settings(scene.voxgi)
    w, h = 64, 48
    gpu_passes, timings = render_passes_gpu(snapshot, state, w, h, cones, shadows="RAYS")
    # the direct light's dispatches: per sub-pixel pass (anti-aliased) or once
    assert "sub-pixel passes (GPU)" in timings or "direct (GPU)" in timings
    render_passes_gpu(snapshot, state, w, h, cones, shadows="RAYS")
    assert shared_bvh().uploaded_bytes == 0  # the same triangles: no new upload
    numpy_passes, _ = render_passes(snapshot, state, w, h, cones, shadows="RAYS")
    error = relative_l1(gpu_passes["Diffuse Direct"], numpy_passes["Diffuse Direct"])
    glossy = relative_l1(gpu_passes["Glossy Direct"], numpy_passes["Glossy Direct"])
    print(f"preview Diffuse Direct, GPU vs numpy: {error:.5f}, Glossy Direct {glossy:.5f}")
    assert error < 0.01
    if lamps == "five":
        assert glossy < 0.02


def test_every_gather_ray_counts_however_many_there_are(voxgi):
    """llvmpipe ends an invocation's loops after 65535 iterations in all; one dispatch tracing
    all of a point's rays silently dropped those past about the 600th, so 1024 GI rays gave half
    the AO of 64. The rays are now split over dispatches (gpu_gather.rays_per_dispatch)."""
    import gi_scenes

    from voxgi.render.gpu_gather import rays_per_dispatch
    from voxgi.render.pipeline import render_scene_passes

    assert rays_per_dispatch(1) == 16 and rays_per_dispatch(1, others=39) == 1
    # a hit traces the one lamp it picks; the pick's loops over 40 lamps count too
    assert 1 < rays_per_dispatch(40) < 16
    scene = bpy.context.scene
    gi_scenes.build("thin_wall_rooms", scene)
    means = {}
    for rays in (64, 1024):
        scene.voxgi.gi_rays = rays
        passes, _ = render_scene_passes(bpy.context, scene, None, 24, 18)
        means[rays] = float(np.asarray(passes["Ambient Occlusion"])[..., 0].mean())
    assert means[1024] == pytest.approx(means[64], rel=0.03), means

"""Every light Cycles has (issue 17): the world (an HDRI through a Mapping node, a uniform sky)
and emissive surfaces light the preview, on the GPU as in the numpy reference, through F12 and
``voxgi.render_preview`` alike, and close to Cycles (tests/data/light_refs, made by
tools/make_light_references.py with Cycles' default pixel filter).
"""
from __future__ import annotations

import json
import pathlib

import bpy
import light_scenes
import numpy as np
import pytest

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "light_refs"
PASSES = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect")


def relative_l1(ours, reference, mask):
    return float(np.abs(ours[mask] - reference[mask]).sum() / max(np.abs(reference[mask]).sum(), 1e-12))


def preview(name, tracer="AUTO", width=light_scenes.WIDTH, height=light_scenes.HEIGHT,
            sparse=True):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    light_scenes.build(name, scene)
    scene.voxgi.tracer = tracer
    scene.voxgi.sparse_gathers = sparse
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


@pytest.mark.parametrize("name", ["hdri_courtyard", "sky_courtyard", "emissive_room", "metal_room"])
def test_numpy_and_gpu_draw_the_same_light(voxgi, name):
    """The world map (importance-sampled, MIS with the cosine), the emissive triangles (exact
    sum, shadow rays by power) and the metals' glossy rays (METAL_RAY_FACTOR × a dielectric's)
    are the same samples in numpy and GLSL. Every gather point is traced: the sparse gather
    plans its points on each tracer's own G-buffer (raster against ray cast), and where a
    borderline cell is traced by one and filled by the other the two differ by that cell's
    noise, not by their light samples (test_sparse_gathers and test_multibounce compare the
    sparse gathers)."""
    gpu = preview(name, "AUTO", 64, 48, sparse=False)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reference = preview(name, "NUMPY", 64, 48, sparse=False)
    everywhere = np.ones((48, 64), bool)
    assert reference["Diffuse Direct"].mean() > 0.01
    for pass_name in PASSES:
        assert relative_l1(gpu[pass_name], reference[pass_name], everywhere) <= 0.02, pass_name


def test_an_hdri_lights_the_scene_with_its_sun(voxgi):
    """The courtyard lit only by an HDRI (no lamp): the ground gets the sun's sharp shadows and the
    sky's light in them — not the black image it used to be."""
    ours = preview("hdri_courtyard")
    direct = ours["Diffuse Direct"].sum(-1)
    lit = direct[direct > 0]
    assert lit.size > 0.5 * direct.size
    # sunlit ground against ground in the walls' shadows: sharp, and the shade is the sky's blue
    bright, shade = np.percentile(lit, 95), np.percentile(lit, 5)
    assert bright > 3 * shade > 0.02 * bright  # the shade holds the sky's light, not black


@pytest.mark.parametrize("name", sorted(light_scenes.SCENES))
def test_default_preview_against_cycles(voxgi, name):
    """Relative L1 against Cycles 2048 spp (one bounce of either kind, default pixel filter) at
    the limits of tests/data/light_refs/limits.json; each scene's Cycles 16 spp + OIDN errors are
    printed beside ours."""
    reference_path = REFS / f"{name}.npz"
    ours = preview(name)
    with np.load(reference_path) as data:
        reference = {key: data[key].astype(np.float64) for key in data.files}
    limits = json.loads((REFS / "limits.json").read_text())[name]
    quick = json.loads((REFS / "cycles_spp.json").read_text())[name]["checks"]["16+OIDN"]
    mask = reference["Alpha"] > 0.5
    errors = {p: relative_l1(ours[p], reference[p], mask) for p in limits}
    print(name, {k: round(v, 4) for k, v in errors.items()}, "Cycles 16 spp + OIDN",
          quick["relative_l1"])
    for pass_name, error in errors.items():
        assert error <= limits[pass_name], (pass_name, error, limits[pass_name])


def test_an_emission_shader_lights_like_principled_emission(voxgi):
    """The ceiling panel as an Emission shader (Color × Strength) instead of a Principled BSDF's
    emission: the same light on the room; the panel itself reflects nothing."""
    principled = preview("emissive_room", "AUTO", 64, 48)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    light_scenes.build("emissive_room", scene)
    material = bpy.data.materials["Panel Glow"]
    tree = material.node_tree
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 0.9, 0.8, 1.0)
    emission.inputs["Strength"].default_value = 6.0
    tree.links.new(emission.outputs["Emission"], tree.get_output_node("ALL").inputs["Surface"])
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    from voxgi.render.pipeline import render_scene_passes

    passes, _ = render_scene_passes(bpy.context, scene, None, 64, 48)
    shader = {k: np.asarray(v, np.float64) for k, v in passes.items()}
    # away from the panel (whose own colour differs, edge pixels included)
    both = (np.abs(principled["Diffuse Color"] - shader["Diffuse Color"]).sum(-1) < 1e-3) & \
        (shader["Diffuse Color"].sum(-1) > 0)
    assert both.mean() > 0.5
    assert relative_l1(shader["Diffuse Direct"], principled["Diffuse Direct"], both) < 0.02
    # the panel's pixels: less diffuse colour than the Principled panel had, and they glow
    panel = shader["Diffuse Color"].sum(-1) < principled["Diffuse Color"].sum(-1) - 0.5
    assert panel.sum() > 3 and shader["Combined"][panel].mean() > 2.0


def field_preview(tracer="AUTO", width=128, height=96):
    """The emissive room at GI Resolution Half: one gather point per 2 × 2 pixels."""
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    light_scenes.build("emissive_room", scene)
    scene.voxgi.tracer = tracer
    scene.voxgi.gi_resolution = "2"
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


def test_the_emitters_sums_are_a_field_of_the_gather_points(voxgi, monkeypatch):
    """The emitters' per-triangle sums — the LTC integral of the glossy lobe and Lambert's exact
    unshadowed Diffuse Direct over every emissive triangle — are evaluated at the gather points
    (one per GI block) and brought to the pixel centres, and to the sub-pixel samples that see
    another surface than their centre, by the joint-bilateral upsample (docs/gi_pipeline.md
    "Where a preview's time goes"); a point evaluates them itself only where that field does
    not hold (its light turns by more than NEAR_STEP of its lobe's width across the taps: near
    the emitters); a sample that sees its centre's surface takes the centre's. Evaluated at
    every pixel centre and again at those samples, they were over three quarters of the
    emissive room's render at 640 × 480. Against that design the field moves the image by
    less than 1.5%."""
    from voxgi.render import gpu_bvh, gpu_compose, gpu_preview
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.gi.emitters import NEAR_STEP
    from voxgi.voxgi_addon.preview.passes import same_surface
    from voxgi.voxgi_addon.preview.upsample import low_shape

    calls = {"emitter_fields": [], "emitter_glossy_texture": [],
             "emitters_unshadowed_texture": [], "direct_light_texture": []}
    real = {name: getattr(gpu_compose if name == "direct_light_texture" else gpu_preview, name)
            for name in calls}

    def recorder(name):
        def call(*args, **kwargs):
            out = real[name](*args, **kwargs)
            calls[name].append((args, kwargs, out))
            return out
        return call

    for name in calls:
        monkeypatch.setattr(gpu_compose if name == "direct_light_texture" else gpu_preview, name,
                            recorder(name))
    gpu = field_preview()
    monkeypatch.undo()
    # the sums at the gather points: one dispatch each over the gathers' layout
    (_, _, (low_glossy, low_diffuse, *_)), = calls["emitter_fields"]
    for low in (low_glossy, low_diffuse):
        assert (low.height, low.width) == low_shape(96, 128, 2)
    assert calls["emitter_glossy_texture"][0][1]["unshadowed"]

    def texels(texture):
        return read_texture(texture).reshape(-1, 4)

    def blind(texture):  # the field with its light 0, its turns kept
        values = read_texture(texture).copy()
        values[..., :3] = 0.0
        return float_texture(values, (texture.width, texture.height))

    # Then the centres' glossy light and unshadowed sums, and each sub-pixel pass's glossy
    # light and Diffuse Direct: with the field's light 0 the points it serves go dark, the
    # others are what they were (evaluated there)
    evaluated = {}  # (centres or passes, kind) → [points evaluated, points that see a surface]
    checked = [(name, call) for name in ("emitter_glossy_texture", "emitters_unshadowed_texture")
               for call in calls[name][1:]]
    checked += [("direct_light_texture", call) for call in calls["direct_light_texture"]
                if call[1].get("centre") is not None and call[1].get("field") is not None]
    assert len(checked) == 2 + 16 + 16  # the centres, the passes' glossy light and their direct
    for name, (args, kwargs, out) in checked:
        field = kwargs["field"]
        dark = texels(real[name](*args, **{**kwargs, "field": blind(field)}))
        out, turn = texels(out), texels(field)[:, 3]
        seen = {key: texels(args[1][f"gbuffer_{key}"]) for key in ("position", "normal", "view")}
        hit = seen["position"][:, 3] > 0.5
        same = np.zeros_like(hit)
        if kwargs.get("centre") is not None:  # a pass: its centre's surface takes the centre's
            centre = {key: texels(value) for key, value in kwargs["centre"].items()}
            same = hit & same_surface(
                hit, np.rint(seen["view"][:, 3]), seen["position"][:, :3], seen["normal"][:, :3],
                centre["gbuffer_position"][:, 3] > 0.5, np.rint(centre["gbuffer_view"][:, 3]),
                centre["gbuffer_position"][:, :3], centre["gbuffer_normal"][:, :3])
            assert np.array_equal(dark[same, :3], out[same, :3])
        held = hit & ~same & (dark[:, :3] == 0).all(axis=1) & (out[:, :3] > 0).any(axis=1)
        own = hit & ~same & ~held
        assert held.any(), name
        assert ((turn[held] >= 0) & (turn[held] <= NEAR_STEP)).all(), name
        assert np.allclose(dark[own, :3], out[own, :3], rtol=1e-5, atol=1e-7), name
        key = ("passes" if kwargs.get("centre") is not None else "centres",
               "glossy" if name == "emitter_glossy_texture" else "diffuse")
        count = evaluated.setdefault(key, [0, 0])
        count[0], count[1] = count[0] + own.sum(), count[1] + hit.sum()
    # at the centres the glossy lobe (roughness 0.5: width 2α = 0.5) needs the sums at more
    # points than the diffuse one; the passes evaluate them at few of their points
    shares = {key: own / seen for key, (own, seen) in evaluated.items()}
    assert shares[("centres", "glossy")] < 0.5 and shares[("centres", "diffuse")] < 0.25, shares
    assert shares[("passes", "glossy")] < 0.1 and shares[("passes", "diffuse")] < 0.1, shares

    # against the sums evaluated at every centre and sample (never held: the design before)
    monkeypatch.setattr(gpu_bvh, "NEAR_STEP", -1.0)
    monkeypatch.setattr(gpu_bvh, "_shaders", {})  # built with it, dropped after
    exact = field_preview()
    everywhere = np.ones((96, 128), bool)
    for name, limit in (("Combined", 0.004), ("Diffuse Direct", 0.015), ("Glossy Direct", 0.015)):
        assert relative_l1(gpu[name], exact[name], everywhere) <= limit, name


def test_numpy_reads_the_emitters_field_as_the_gpu(voxgi, monkeypatch):
    """The numpy tracer builds the emitters' field at the same gather points
    (``passes.emitter_field``, ``upsample.EmitterField``), evaluates their sums at the same
    points besides, and draws the same light as the GPU within 2% per pass."""
    from voxgi.voxgi_addon.gi import exact_glossy
    from voxgi.voxgi_addon.preview import passes
    from voxgi.voxgi_addon.preview.upsample import low_shape

    gpu = field_preview("AUTO", 64, 48)
    points = {"unshadowed": [], "glossy": []}
    real_sum, real_glossy = passes.emitters_unshadowed_at, exact_glossy._emitters_unshadowed

    def summed(emitters, p, n):
        points["unshadowed"].append(len(p))
        return real_sum(emitters, p, n)

    def shone(lobe, emitters, p, glossy):
        points["glossy"].append(len(p))
        return real_glossy(lobe, emitters, p, glossy)

    monkeypatch.setattr(passes, "emitters_unshadowed_at", summed)
    monkeypatch.setattr(exact_glossy, "_emitters_unshadowed", shone)
    reference = field_preview("NUMPY", 64, 48)
    cells = int(np.prod(low_shape(48, 64, 2)))
    pixels = int((reference["Alpha"] > 0).sum())
    for kind, counted in points.items():
        # the gather points (those that see a surface), then the centres the field does not
        # serve (near the emitters: with 32 × 24 gather points, three quarters of the room for
        # the glossy lobe of roughness 0.5), then each pass's
        assert 0.5 * cells < counted[0] <= cells, (kind, counted)
        assert counted[1] < 0.9 * pixels and len(counted) == 2 + 16, (kind, counted, pixels)
    everywhere = np.ones((48, 64), bool)
    for name in PASSES:
        assert relative_l1(gpu[name], reference[name], everywhere) <= 0.02, name


def test_gather_points_on_metals_trace_ao_only_and_the_image_keeps_its_light(voxgi,
                                                                             monkeypatch):
    """The room of metals at 160 × 120: the points whose surface shows no diffuse light (the
    full metals, counted from the plan) draw AO_RAYS each, and the preview's passes stay
    within the scene's limits and within noise of the one that draws every ray everywhere."""
    from voxgi.voxgi_addon.preview import sparse_gather

    counted = []
    counts_of = sparse_gather.ray_counts
    monkeypatch.setattr(sparse_gather, "ray_counts",
                        lambda cells, diffuse, rays: counted.append(
                            (counts_of(cells, diffuse, rays), cells, diffuse, rays))
                        or counted[-1][0])
    ours = preview("metal_room")
    counts, cells, diffuse, rays = counted[0]
    metal = cells & ~diffuse
    assert metal.sum() > 0.5 * cells.sum()  # most of the room is metal
    assert (counts[metal] == sparse_gather.AO_RAYS).all() and (counts[cells & diffuse] == rays).all()
    monkeypatch.setattr(sparse_gather, "AO_RAYS", 10 ** 6)  # every point its full rays
    bpy.ops.wm.read_factory_settings(use_empty=True)
    full = preview("metal_room")
    with np.load(REFS / "metal_room.npz") as data:
        reference = {key: data[key].astype(np.float64) for key in data.files}
    mask = reference["Alpha"] > 0.5
    limits = json.loads((REFS / "limits.json").read_text())["metal_room"]
    for pass_name, limit in limits.items():
        assert relative_l1(ours[pass_name], reference[pass_name], mask) <= limit, pass_name
    assert relative_l1(ours["Combined"], full["Combined"], mask) <= 0.01
    assert relative_l1(ours["Ambient Occlusion"], full["Ambient Occlusion"], mask) <= 0.05


@pytest.mark.parametrize("name, width, height", [("sky_courtyard", 64, 48),
                                                  ("hdri_courtyard", 128, 96)])
def test_fewer_world_strata_at_the_pixels_are_the_same_in_numpy_and_gpu(voxgi, monkeypatch, name,
                                                                        width, height):
    """Where the world's filter is wide (here forced at a small size: passes.WORLD_FEWER_FROM
    2) the pixel centres' world rays go over a quarter fewer strata a side (9 instead of 16)
    away from the geometry's edges (here in every 8 × 8 block with no edge pixel:
    WORLD_FEWER_REACH 0), the sun's strata kept, and the HDRI courtyard's rest of the map (5%
    of its power) over 2 × 2: numpy and GLSL draw the same rays at the same pixels. (The HDRI
    courtyard's light is mostly its sun, which keeps its strata: it needs more blocks for the
    cut to show.)"""
    from voxgi.render import gpu_preview
    from voxgi.voxgi_addon.preview import passes

    # F12's pixel centres take the rest of the world from the gather points
    # (test_the_world_s_light_at_the_gather_points_is_the_pixels_own); the pixels' own rays
    # are what the numpy tracer and a preview without the gathers' filter draw
    monkeypatch.setattr(gpu_preview, "WORLD_AT_POINTS", False)
    full = preview(name, "AUTO", width, height, sparse=False)
    monkeypatch.setattr(passes, "WORLD_FEWER_FROM", 2)
    monkeypatch.setattr(passes, "WORLD_FEWER_REACH", 0)
    assert passes.world_strata_side(16, width, height) == 3
    bpy.ops.wm.read_factory_settings(use_empty=True)
    gpu = preview(name, "AUTO", width, height, sparse=False)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reference = preview(name, "NUMPY", width, height, sparse=False)
    everywhere = np.ones((height, width), bool)
    # the same rays, not only the same estimate: numpy and GLSL lie closer to each other than
    # to the 16 strata' image
    apart = relative_l1(gpu["Diffuse Direct"], full["Diffuse Direct"], everywhere)
    same = relative_l1(gpu["Diffuse Direct"], reference["Diffuse Direct"], everywhere)
    print(f"{name}: numpy and GLSL {same:.6f} apart, the 16 strata' image {apart:.6f}")
    assert same < apart / 2
    for pass_name in PASSES:
        assert relative_l1(gpu[pass_name], reference[pass_name], everywhere) <= 0.02, pass_name


@pytest.mark.parametrize("name", ["sky_courtyard", "hdri_courtyard"])
def test_the_world_s_light_at_the_gather_points_is_the_pixels_own(voxgi, monkeypatch, name):
    """F12 takes the rest of the world's light hidden from a pixel (all of a uniform sky's, a
    map's without its sun) from the diffuse gather's own rays at the gather points (each ray
    a surface stops adds the world's rest along it: bvh_gather.glsl out_hidden), filters and
    upsamples it like the indirect light, and subtracts it from the world's exact unshadowed
    light at every pixel (docs/gi_pipeline.md "The world's light at the gather points", "The
    world's rest from the diffuse gather's own rays"): the image is the one the pixels' own
    rays give, within their noise."""
    from voxgi.render import gpu_preview

    width, height = 160, 120
    scene = bpy.context.scene
    light_scenes.build(name, scene)
    from voxgi.render.pipeline import render_scene_passes

    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert "world light at the gather points (GPU)" in lines[-1][1], lines
    points = {k: np.asarray(v, np.float64) for k, v in passes.items()}
    monkeypatch.setattr(gpu_preview, "WORLD_AT_POINTS", False)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    light_scenes.build(name, scene := bpy.context.scene)
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert "world light at the gather points" not in lines[-1][1]
    own = {k: np.asarray(v, np.float64) for k, v in passes.items()}
    seen = own["Diffuse Color"].sum(-1) > 0
    direct = (points["Diffuse Direct"][seen].sum(), own["Diffuse Direct"][seen].sum())
    print(name, "Diffuse Direct summed, points / pixels' own rays:", direct[0] / direct[1],
          "apart:", relative_l1(points["Diffuse Direct"], own["Diffuse Direct"], seen))
    assert abs(direct[0] / direct[1] - 1.0) <= 0.01
    assert relative_l1(points["Diffuse Direct"], own["Diffuse Direct"], seen) <= 0.03
    # the other passes are the same frame's
    for pass_name in ("Diffuse Indirect", "Glossy Direct", "Glossy Indirect"):
        assert relative_l1(points[pass_name], own[pass_name], seen) <= 0.01, pass_name


def test_a_glowing_sphere_of_thousands_of_triangles_lights_the_room(voxgi, monkeypatch):
    """The emissive room's glowing sphere at 64 × 32 segments (3,968 emissive triangles with
    the panel's, past MAX_EMITTER_TRIANGLES): the GPU preview lights the room as it does with
    the exact sums over every triangle (their proxy's sums, their own shadow rays), and as the
    numpy tracer does. Before, such emitters were no light: the room's Diffuse Direct lost the
    panel's and the sphere's light (their emission only seen by the gathers' rays)."""
    from voxgi.voxgi_addon.gi import emitters

    def with_orb(tracer):
        scene = bpy.context.scene
        light_scenes.build("emissive_room", scene)
        orb = next(o for o in scene.objects if o.type == "MESH" and o.data.materials and
                   o.data.materials[0].name.startswith("Orb"))
        material, location = orb.data.materials[0], tuple(orb.location)
        bpy.data.objects.remove(orb)
        bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=0.3,
                                             location=location)
        bpy.context.active_object.data.materials.append(material)
        scene.voxgi.tracer = tracer
        scene.voxgi.sparse_gathers = False
        from voxgi.blender.session import scene_session
        from voxgi.render.pipeline import render_scene_passes
        passes, lines = render_scene_passes(bpy.context, scene, None, 64, 48)
        assert scene_session(scene.name_full).tracer_used == (
            "GPU" if tracer == "AUTO" else "numpy"), lines
        bpy.ops.wm.read_factory_settings(use_empty=True)
        return {k: np.asarray(v, np.float64) for k, v in passes.items()}

    ours = with_orb("AUTO")
    numpy_ours = with_orb("NUMPY")
    with monkeypatch.context() as m:
        m.setattr(emitters, "MAX_EMITTER_TRIANGLES", 10_000)
        exact = with_orb("AUTO")
    everywhere = np.ones((48, 64), bool)
    assert exact["Diffuse Direct"].mean() > 0.05
    for name in ("Diffuse Direct", "Glossy Direct", "Combined"):
        error = relative_l1(ours[name], exact[name], everywhere)
        print(name, "proxy vs exact sums", round(error, 4),
              "GPU vs numpy", relative_l1(ours[name], numpy_ours[name], everywhere))
        assert error < 0.02, name
        assert relative_l1(ours[name], numpy_ours[name], everywhere) < 0.02, name

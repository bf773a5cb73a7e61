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


def preview(name, tracer="AUTO", width=light_scenes.WIDTH, height=light_scenes.HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    light_scenes.build(name, scene)
    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


@pytest.mark.parametrize("name", ["hdri_courtyard", "sky_courtyard", "emissive_room", "metal_room"])
def test_numpy_and_gpu_draw_the_same_light(voxgi, name):
    """The world map (importance-sampled, MIS with the cosine), the emissive triangles (exact
    sum, shadow rays by power) and the metals' glossy rays (METAL_RAY_FACTOR × a dielectric's)
    are the same samples in numpy and GLSL."""
    gpu = preview(name, "AUTO", 64, 48)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reference = preview(name, "NUMPY", 64, 48)
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


def test_the_emitters_glossy_light_is_evaluated_at_the_pixel_centres(voxgi, monkeypatch):
    """The emitters' glossy light (the LTC integral over every emissive triangle and shadow
    rays, shaders/bvh_emitter_glossy.glsl) is evaluated once at the pixel centres; a sub-pixel
    pass takes the centre's value wherever it sees the surface its pixel's centre sees and
    evaluates only the rest (evaluated per pass at every edge pixel it was over half of the
    emissive room's render). numpy splits the passes alike and draws the same light."""
    from voxgi.render import gpu_preview
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.voxgi_addon.preview.passes import same_surface

    calls = []
    evaluate = gpu_preview.emitter_glossy_texture

    def recorded(bvh, inputs, *args, centre=None, **kwargs):
        out = evaluate(bvh, inputs, *args, centre=centre, **kwargs)
        calls.append((inputs, centre, out))
        return out

    monkeypatch.setattr(gpu_preview, "emitter_glossy_texture", recorded)
    gpu = preview("emissive_room", "AUTO", 64, 48)
    assert [centre is None for _, centre, _ in calls] == [True] + [False] * 16  # no glass
    reused = seen = 0
    for inputs, centre, out in calls[1:]:
        texels = {name: read_texture(texture).reshape(-1, 4) for name, texture in
                  (("position", inputs["gbuffer_position"]), ("normal", inputs["gbuffer_normal"]),
                   ("view", inputs["gbuffer_view"]), ("centre", centre["gbuffer_position"]),
                   ("centre normal", centre["gbuffer_normal"]),
                   ("centre view", centre["gbuffer_view"]), ("shine", centre["shine"]),
                   ("out", out))}
        hit = texels["position"][:, 3] > 0.5
        same = hit & same_surface(hit, np.rint(texels["view"][:, 3]), texels["position"][:, :3],
                                  texels["normal"][:, :3], texels["centre"][:, 3] > 0.5,
                                  np.rint(texels["centre view"][:, 3]),
                                  texels["centre"][:, :3], texels["centre normal"][:, :3])
        # the centre's value itself where the pass sees its surface (evaluated, it would differ)
        equal = np.all(texels["out"][same, :3] == texels["shine"][same, :3], axis=1)
        assert equal.mean() > 0.99 and (texels["shine"][same, :3] > 0).any()
        reused, seen = reused + same.sum(), seen + hit.sum()
    assert reused > 0.75 * seen, (reused, seen)

    assert_numpy_evaluates_centres_once(monkeypatch, "emitters_shine", 0, seen, gpu,
                                        "Glossy Direct")


def test_the_emitters_unshadowed_light_is_evaluated_at_the_pixel_centres(voxgi, monkeypatch):
    """The exact unshadowed sum of the emitters' Diffuse Direct (Lambert's formula over every
    emissive triangle: emitters.unshadowed_sum, bvh_lights.glsl emitters_unshadowed) is
    evaluated once at the pixel centres; a pass takes its centre's sum wherever it sees the
    surface its pixel's centre sees and evaluates only the rest, and keeps its own shadow rays
    (evaluated in every pass at every texel, the emitters' dispatches were a quarter of the
    emissive room's render). numpy splits the passes alike and draws the same light."""
    from voxgi.render import gpu_compose, gpu_preview
    from voxgi.render.gpu_scene import GPUScene
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.voxgi_addon.preview.passes import same_surface

    centres, calls = [], []
    unshadowed = gpu_preview.emitters_unshadowed_texture
    direct = gpu_compose.direct_light_texture

    def summed(bvh, inputs, *args, **kwargs):
        centres.append(inputs)
        return unshadowed(bvh, inputs, *args, **kwargs)

    def recorded(bvh, inputs, *args, **kwargs):
        out = direct(bvh, inputs, *args, **kwargs)
        if kwargs.get("centre") is not None:  # the world's and emitters' dispatch
            calls.append((bvh, inputs, args, kwargs, out))
        return out

    monkeypatch.setattr(gpu_preview, "emitters_unshadowed_texture", summed)
    monkeypatch.setattr(gpu_compose, "direct_light_texture", recorded)
    gpu = preview("emissive_room", "AUTO", 64, 48)
    assert len(centres) == 1 and len(calls) == 1 + 16  # the centre pass, the sub-pixel passes
    reused = seen = 0
    for index, (bvh, inputs, args, kwargs, out) in enumerate(calls):
        # with a centre sum of zeros the texels that take their centre's go dark, the others
        # evaluate theirs as the pass did (the scene has no world: the emitters' light alone)
        centre = kwargs["centre"]
        size = (out.width, out.height)
        dark = direct(bvh, inputs, *args, **{**kwargs, "centre": {
            **centre, "unshadowed": GPUScene.zeros(*size)}})
        texels = {name: read_texture(texture).reshape(-1, 4) for name, texture in
                  (("position", inputs["gbuffer_position"]), ("normal", inputs["gbuffer_normal"]),
                   ("view", inputs["gbuffer_view"]), ("centre", centre["gbuffer_position"]),
                   ("centre normal", centre["gbuffer_normal"]),
                   ("centre view", centre["gbuffer_view"]), ("out", out), ("dark", dark))}
        hit = texels["position"][:, 3] > 0.5
        same = hit & same_surface(hit, np.rint(texels["view"][:, 3]), texels["position"][:, :3],
                                  texels["normal"][:, :3], texels["centre"][:, 3] > 0.5,
                                  np.rint(texels["centre view"][:, 3]),
                                  texels["centre"][:, :3], texels["centre normal"][:, :3])
        if index == 0:  # the centre pass over the image: its own centres, no sum evaluated
            assert same.sum() == hit.sum() > 0 and not texels["dark"][:, :3].any()
            continue
        other = hit & ~same
        assert (texels["dark"][same, :3] == 0).all(axis=1).mean() > 0.99
        assert (texels["out"][same, :3] > 0).any() and other.any()
        assert (texels["dark"][other, :3] == texels["out"][other, :3]).all(axis=1).mean() > 0.99
        reused, seen = reused + same.sum(), seen + hit.sum()
    assert reused > 0.75 * seen, (reused, seen)

    assert_numpy_evaluates_centres_once(monkeypatch, "emitters_unshadowed_at", 1, seen, gpu,
                                        "Diffuse Direct")


def assert_numpy_evaluates_centres_once(monkeypatch, function, point_arg, seen, gpu, pass_name):
    """The numpy tracer's emissive room (64 × 48) with ``passes.<function>`` counted (its
    points are argument ``point_arg``): evaluated at the pixel centres once, never in the
    centre pass, and in the sub-pixel passes at fewer than a quarter of the GPU's ``seen``
    pass hits; Combined and ``pass_name`` within 0.02 of the ``gpu`` passes."""
    from voxgi.voxgi_addon.preview import passes

    points = []
    evaluate = getattr(passes, function)

    def counted(*args, **kwargs):
        points.append(len(args[point_arg]))
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(passes, function, counted)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reference = preview("emissive_room", "NUMPY", 64, 48)
    # the pixel centres once, then only the points of the passes that see another surface
    assert len(points) == 1 + 1 + 16 and points[1] == 0, points  # the centre pass: none
    assert sum(points[2:]) < 0.25 * seen, (points, seen)  # the GPU's passes' hits
    everywhere = np.ones((48, 64), bool)
    for name in ("Combined", pass_name):
        assert relative_l1(gpu[name], reference[name], everywhere) <= 0.02, name

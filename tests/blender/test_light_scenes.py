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

"""Glossy reflections of the default preview (Accurate: exact rays from the GGX visible normals,
voxgi_addon/gi/exact_glossy.py) against Cycles, on the test Cornell box with its white surfaces
turned to brushed metal (metallic 1, roughness 0.3): the floor, back wall, ceiling and blocks
mirror the red and green walls. Cycles renders the reference (1024 spp) and its own 64-spp
estimate in the test, one bounce of either kind, as tools/make_gi_references.py does."""
import bpy
import numpy as np
import scenes
from cycles_reference import render_cycles_passes

WIDTH, HEIGHT = 80, 60


def relative_l1(ours, reference, mask):
    ours, reference = np.asarray(ours, np.float64), np.asarray(reference, np.float64)
    return float(np.abs(ours[mask] - reference[mask]).sum() / np.abs(reference[mask]).sum())


def metal_box():
    scene = bpy.context.scene
    scenes.build_test_cornell_box(scene, light="AREA")
    bsdf = bpy.data.materials["Test White"].node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.3
    # point samples, as the references here are rendered (a pure metal's pixels are then metal
    # only, not blended with an edge's neighbours by the pixel filter)
    scene.cycles.filter_width = 0.01
    return scene


def preview(scene, tracer):
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.tracer = tracer
    passes, _ = render_scene_passes(bpy.context, scene, None, WIDTH, HEIGHT)
    return passes


def test_metal_reflections_beat_cycles_64_spp(voxgi):
    scene = metal_box()
    one_bounce = {"ao_distance": scene.voxgi.ao_distance, "glossy_bounces": 1, "filter_width": 0.01}
    reference = render_cycles_passes(scene, WIDTH, HEIGHT, 1024, seed=0, **one_bounce)
    cycles_64 = render_cycles_passes(scene, WIDTH, HEIGHT, 64, seed=1, **one_bounce)
    ours = preview(scene, "AUTO")
    mask = reference["Alpha"] > 0.5
    errors = {name: (relative_l1(ours[name], reference[name], mask),
                     relative_l1(cycles_64[name], reference[name], mask))
              for name in ("Glossy Indirect", "Glossy Direct", "Combined")}
    print({name: tuple(round(e, 3) for e in pair) for name, pair in errors.items()})
    for name in ("Glossy Indirect", "Combined"):
        ours_error, cycles_error = errors[name]
        assert ours_error < cycles_error, (name, ours_error, cycles_error)
    assert errors["Glossy Direct"][0] <= 0.03  # the lights' own reflections (4 × 4 grid)
    # a pure metal has no diffuse passes, in Cycles and here
    metal = np.all(reference["Diffuse Color"] == 0.0, axis=-1) & mask
    assert metal.any() and not np.asarray(ours["Diffuse Indirect"])[metal].any()


def test_numpy_and_gpu_glossy_gathers_agree(voxgi):
    scene = metal_box()
    gpu = preview(scene, "AUTO")
    reference = preview(scene, "NUMPY")
    everywhere = np.ones((HEIGHT, WIDTH), bool)
    for name in ("Glossy Indirect", "Glossy Direct", "Glossy Color", "Combined"):
        assert relative_l1(gpu[name], reference[name], everywhere) <= 0.02, name

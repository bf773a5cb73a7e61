"""The default preview (GPU, Accurate quality, Auto voxel fit, default settings) on four scenes
nobody tuned for, against Cycles 2048 spp with one bounce (tests/data/gi_refs, made by
tools/make_gi_references.py; docs/gi_pipeline.md "Error budget" describes the scenes and "What
one bounce means in Cycles" the light paths).

Targets, relative L1 over the pixels that see geometry: Diffuse Direct ≤ 0.03, Diffuse Indirect
≤ 0.12, AO ≤ 0.08, Combined below Cycles' own 64-spp error (tests/data/gi_refs/cycles_spp.json),
and in the thin-wall rooms the dark room's Diffuse Indirect ≤ 2% of the lit room's.
"""
import json
import pathlib

import bpy
import gi_scenes
import numpy as np
import pytest

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "gi_refs"
TARGETS = {"Diffuse Direct": 0.03, "Diffuse Indirect": 0.12, "Ambient Occlusion": 0.08}


def relative_l1(ours, reference, mask):
    return float(np.abs(ours[mask] - reference[mask]).sum() / np.abs(reference[mask]).sum())


def preview(name, tracer="AUTO", width=gi_scenes.WIDTH, height=gi_scenes.HEIGHT,
            glossy_indirect=True):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    gi_scenes.build(name, scene)
    scene.voxgi.glossy_indirect = glossy_indirect
    scene.voxgi.tracer = tracer
    passes, _ = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy")
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


def test_numpy_and_gpu_agree_on_a_skinned_scene(voxgi):
    """The numpy reference and the GPU path draw the same rays (skinning, sun + area light); the
    glossy cones are left out (their numpy and GLSL marches are compared elsewhere)."""
    gpu = preview("skinned_figure", "AUTO", 80, 60, glossy_indirect=False)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reference = preview("skinned_figure", "NUMPY", 80, 60, glossy_indirect=False)
    everywhere = np.ones((60, 80), bool)
    for name, image in reference.items():
        if not np.abs(image).sum():  # Glossy Indirect: off in both
            assert not np.abs(gpu[name]).sum(), name
            continue
        assert relative_l1(gpu[name], image, everywhere) <= 0.02, name


@pytest.mark.parametrize("name", sorted(gi_scenes.SCENES))
def test_default_preview_against_cycles(voxgi, name):
    ours = preview(name)
    with np.load(REFS / f"{name}.npz") as data:
        reference = {key: data[key].astype(np.float64) for key in data.files}
    cycles_64 = json.loads((REFS / "cycles_spp.json").read_text())[name]["checks"]["64"]
    mask = reference["Alpha"] > 0.5
    errors = {p: relative_l1(ours[p], reference[p], mask)
              for p in ("Diffuse Direct", "Diffuse Indirect", "Ambient Occlusion", "Combined")}
    print(name, {k: round(v, 4) for k, v in errors.items()},
          "Cycles 64 spp Combined", cycles_64["relative_l1"]["Combined"])
    bounds = {**TARGETS, "Combined": cycles_64["relative_l1"]["Combined"]}
    for pass_name, error in errors.items():
        assert error <= bounds[pass_name], (pass_name, error, bounds[pass_name])


def test_thin_wall_does_not_leak(voxgi):
    """The camera looks straight down on the two rooms: image columns left of the wall see the
    lit room, right of it the dark one (gi_scenes.build_thin_wall_rooms)."""
    ours = preview("thin_wall_rooms")
    with np.load(REFS / "thin_wall_rooms.npz") as data:
        alpha = data["Alpha"] > 0.5
    indirect = ours["Diffuse Indirect"].sum(axis=-1)
    half = gi_scenes.WIDTH // 2
    lit = indirect[:, : half - 4][alpha[:, : half - 4]].mean()
    dark = indirect[:, half + 4:][alpha[:, half + 4:]].mean()
    print(f"thin wall: dark room's indirect {dark / lit:.4%} of the lit room's")
    assert lit > 0.0
    assert dark <= 0.02 * lit

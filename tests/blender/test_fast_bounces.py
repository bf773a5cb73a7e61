"""Fast quality at Bounces > 1 (issue 20; voxgi_addon/gi/cone_bounces.py): the voxels the cones
read also reflect the radiance cache's light, so Fast's interiors brighten towards Cycles at its
default light paths (tests/data/bounce_refs, tools/make_bounce_references.py), and numpy and the
GPU agree within 2%.

Fast's limits are looser than Accurate's (test_multibounce.py): its one-bounce cones are already
0.25–0.7 off Cycles' Diffuse Indirect (docs/gi_pipeline.md "Fast quality: world and emission").
The limits are the errors measured at the default Bounces + 15%; each scene must also be closer
to Cycles at the default Bounces than at one bounce."""
from __future__ import annotations

import bounce_scenes
import bpy
import numpy as np
import pytest
from test_multibounce import REFS, follow_cycles, relative_l1

# measured (GPU, 160 × 120) at the default Bounces (one bounce in brackets), Combined /
# Diffuse Indirect: cornell_box 0.127 (0.307) / 0.208 (0.530); emissive_room 0.231 (0.364) /
# 0.408 (0.717); columned_hall 0.210 (0.399) / 0.337 (0.714); textured_room 0.159 (0.301) /
# 0.276 (0.601). The hall re-measured after the radiance cache's faces moved onto their
# surfaces (docs/gi_pipeline.md "Faces start on their surfaces"): its faces under the roof had
# started above it, 15–40× too bright, which made up for the cones' own darkness there;
# Accurate's hall went 0.0575 → 0.048, Fast's 0.210 / 0.337 → 0.238 / 0.393 (the box and the
# textured room 0.132 / 0.218 and 0.163 / 0.286, within their limits).
FAST_LIMITS = {
    "cornell_box": {"Combined": 0.146, "Diffuse Indirect": 0.239},
    "emissive_room": {"Combined": 0.265, "Diffuse Indirect": 0.469},
    "columned_hall": {"Combined": 0.274, "Diffuse Indirect": 0.452},
    "textured_room": {"Combined": 0.183, "Diffuse Indirect": 0.317},
}


def fast_preview(scene, width, height, tracer="AUTO"):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.quality = "FAST"
    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


@pytest.mark.parametrize("name", list(FAST_LIMITS))
def test_fast_default_bounces_closer_to_cycles_default_light_paths(voxgi, name):
    reference = np.load(REFS / f"{name}.npz")
    mask = reference["Alpha"] > 0.5
    errors = {}
    for bounces in ("one", "default"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        bounce_scenes.build(name, scene)
        if bounces == "default":
            follow_cycles(scene)
        ours = fast_preview(scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT)
        errors[bounces] = {p: relative_l1(ours[p], reference[p][..., :3].astype(np.float64), mask)
                           for p in ("Combined", "Diffuse Indirect")}
    print(name, {k: {p: round(e, 4) for p, e in v.items()} for k, v in errors.items()})
    for pass_name, limit in FAST_LIMITS[name].items():
        assert errors["default"][pass_name] < errors["one"][pass_name], pass_name
        assert errors["default"][pass_name] <= limit, (pass_name, errors)


def test_numpy_and_gpu_fast_agree_at_three_bounces(voxgi):
    """The Cornell box at Bounces 3 (a cache of two iterations; numpy's cache and the GPU's are
    gathered separately): every pass within 2%, and the cache's light shows (Diffuse Indirect
    well above one bounce's)."""
    def render(tracer, bounces):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        bounce_scenes.build("cornell_box", scene)
        scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", bounces
        return fast_preview(scene, 64, 48, tracer)

    gpu, numpy = render("AUTO", 3), render("NUMPY", 3)
    one = render("AUTO", 1)
    everywhere = np.ones((48, 64), bool)
    for name in ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Indirect"):
        error = relative_l1(gpu[name], numpy[name], everywhere)
        print(name, round(error, 4))
        assert error <= 0.02, name
    assert gpu["Diffuse Indirect"].mean() > 1.2 * one["Diffuse Indirect"].mean()


def test_thin_wall_dark_room_stays_dark_in_fast(voxgi):
    """The room split by a 2 cm wall, at test_thin_wall_leak.py's voxels (7 cm): at the
    default Bounces Fast's dark side gets ≤ 2% of the lit side's mean Diffuse Indirect (issue
    20's bound; measured 1.9%, 1.3% at one bounce), though the lit side is three times
    brighter than at one bounce."""
    import scenes

    width, height = 128, 64
    lit, dark = scenes.thin_wall_side_masks(width, height)
    means = {}
    for bounces in ("one", "default"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scenes.build_thin_wall_room(scene)
        scene.voxgi.span_mode, scene.voxgi.base_span = "MANUAL", 0.07
        scene.voxgi.grid_resolution = "64"
        if bounces == "default":
            follow_cycles(scene)
        ours = fast_preview(scene, width, height)
        assert ours["Diffuse Direct"][dark].max() == 0.0
        indirect = ours["Diffuse Indirect"].mean(axis=-1)
        means[bounces] = indirect[lit].mean()
        ratio = indirect[dark].max() / means[bounces]
        print(f"thin wall, Fast, {bounces} bounce(s): dark-side max / lit-side mean = {ratio:.4f}")
    assert means["default"] > 2.0 * means["one"]
    assert ratio <= 0.02

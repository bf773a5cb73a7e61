"""Cycles' ray visibility in Fast quality (issue 18; voxgi_addon/gi/ray_views.py): the voxels of
an object hidden from a kind of ray are left out of what that kind of cone marches through —
diffuse cones and AO, glossy cones, the shadow cones and the occupancy that shadows the voxels'
light. On the visibility room (tests/blender/visibility_scenes.py) each toggle changes Fast's
image towards Cycles' (tests/data/visibility_refs, tools/make_visibility_references.py): the
room with every toggle against the same room with one toggle undone, where the two differ."""
from __future__ import annotations

import bpy
import numpy as np
import pytest
import visibility_scenes
from test_visibility_room import REFS, build, relative_l1

WIDTH, HEIGHT = visibility_scenes.WIDTH, visibility_scenes.HEIGHT


def fast_preview(scene, tracer="AUTO", width=WIDTH, height=HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.quality = "FAST"
    scene.voxgi.shadows = "CONES"  # the shadow cones read the voxels too
    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}


@pytest.fixture(scope="module")
def reference():
    with np.load(REFS / "visibility_room.npz") as data:
        return {key: data[key][..., :3].astype(np.float64) for key in data.files if key != "Alpha"}


@pytest.fixture(scope="module")
def toggled(voxgi):
    return fast_preview(build())


def project(points):
    """(N, 2) pixel (column, row from the top) of world points in the room's camera view."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    scene = bpy.context.scene
    out = []
    for p in points:
        ndc = world_to_camera_view(scene, scene.camera, Vector(p))
        out.append((ndc.x * WIDTH, (1.0 - ndc.y) * HEIGHT))
    return np.array(out)


def region(corners):
    """(H, W) bool: the pixels inside the screen box of the world ``corners``."""
    xy = project(corners)
    (x0, y0), (x1, y1) = np.floor(xy.min(axis=0)).astype(int), np.ceil(xy.max(axis=0)).astype(int)
    mask = np.zeros((HEIGHT, WIDTH), bool)
    mask[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = True
    return mask


# name -> (the pass the toggle shows in, the screen box where it shows, the colour channel of the
# hidden object's light there: what must drop (-1: light that must rise, its shadow))
CASES = {
    # the orange pillar camera rays do not see: the G-buffer shows the wall behind it
    "Ghost": ("Diffuse Color", [(-2.3, 0.3, 0.0), (-1.7, 0.9, 0.0), (-2.3, 0.3, 2.2),
                                (-1.7, 0.9, 2.2)], 0),
    # the blue block's shadow on the floor, away from the sun (direction (0.45, 0.75, -0.5))
    # (a 0.8 × 0.8 × 1 m block at (0.5, −0.3): its shadow reaches 0.9 m along x, 1.5 m along y)
    "Shadowless": ("Diffuse Direct", [(0.1, 0.1, 0.0), (1.8, 0.1, 0.0), (0.1, 1.6, 0.0),
                                      (1.8, 1.6, 0.0)], -1),
    # the right wall and floor beside the red panel: red bounce light
    "Unbounced": ("Diffuse Indirect", [(2.9, -0.3, 0.0), (2.9, 1.9, 2.2), (1.6, -0.3, 0.0),
                                       (1.6, 1.9, 0.0)], 0),
    # the mirror panel behind the green block: its green reflection
    "Unreflected": ("Glossy Indirect", [(-1.2, 2.45, 0.3), (0.4, 2.45, 0.3), (0.4, 2.45, 1.9),
                                        (-1.2, 2.45, 1.9)], 1),
}


@pytest.mark.parametrize("name", list(CASES))
def test_toggle_moves_fast_towards_cycles(voxgi, toggled, reference, name):
    """With the toggle undone the hidden object is back: itself (visible_camera, Fast's
    G-buffer), its shadow (visible_shadow), its bounce light (visible_diffuse) or its reflection
    (visible_glossy, the voxels), and where it changes the image the room with the toggle is
    closer to Cycles."""
    pass_name, corners, channel = CASES[name]
    scene = build()
    prop, value = visibility_scenes.TOGGLES[name]
    setattr(bpy.data.objects[name], prop, not value)
    undone = fast_preview(scene)
    box = region(corners)
    ours, theirs, cycles = toggled[pass_name], undone[pass_name], reference[pass_name]
    changed = box & (np.abs(ours - theirs).sum(-1) > 0.05 * np.maximum(theirs.sum(-1), 0.02))
    print(f"{name}: {pass_name} changed at {changed.sum()} of {box.sum()} pixels in its box")
    assert changed.sum() >= 0.1 * box.sum()  # the toggle shows in Fast's image
    if channel < 0:  # the shadow is gone: more light there
        assert ours[changed].mean() > 1.3 * theirs[changed].mean()
    else:  # the hidden object's colour is gone: less of its channel, relative to the others
        share = [p[changed][:, channel].sum() / p[changed].sum() for p in (ours, theirs, cycles)]
        print(f"  channel {channel} share: toggled {share[0]:.3f}, undone {share[1]:.3f}, "
              f"Cycles {share[2]:.3f}")
        assert share[0] < share[1]
        assert abs(share[0] - share[2]) < abs(share[1] - share[2])  # closer to Cycles' colour
    errors = [relative_l1(p, cycles, changed) for p in (ours, theirs)]
    print(f"  relative L1 vs Cycles there: toggled {errors[0]:.3f}, undone {errors[1]:.3f}")
    # (Fast's glossy cones are far from Cycles' mirror anyway: 0.93 against 1.07 measured)
    assert errors[0] < errors[1]


def test_numpy_and_gpu_fast_agree_with_toggles(voxgi):
    """The numpy reference and the GPU's Fast passes within 2% with every toggle (glossy and
    shadow cones through their own octrees)."""
    gpu = fast_preview(build(), "AUTO", 64, 48)
    numpy = fast_preview(build(), "NUMPY", 64, 48)
    everywhere = np.ones((48, 64), bool)
    for name in ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Indirect"):
        error = relative_l1(gpu[name], numpy[name], everywhere)
        print(name, round(error, 4))
        assert error <= 0.02, name

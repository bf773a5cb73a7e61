"""The GI scenes (gi_scenes.py) still match their stored Cycles references (tests/data/gi_refs).

Cheap: no render. VoxGI's exact primary visibility of each scene must cover the same pixels as
the reference's alpha, and the stored passes must be finite, non-negative and the size of the
camera's image. Rebuild the references with tools/make_gi_references.py after changing a scene.
"""
import pathlib

import bpy
import gi_scenes
import numpy as np
import pytest

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "gi_refs"
STORED = ("Diffuse Direct", "Diffuse Indirect", "Diffuse Color", "Ambient Occlusion", "Combined")


@pytest.mark.parametrize("name", sorted(gi_scenes.SCENES))
def test_scene_matches_its_reference(voxgi, name):
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.scene.geometry import world_triangles
    from voxgi.voxgi_addon.scene.raycast import primary_visibility

    scene = bpy.context.scene
    gi_scenes.build(name, scene)
    with np.load(REFS / f"{name}.npz") as data:
        reference = {key: data[key].astype(np.float32) for key in data.files}
    assert set(STORED) <= set(reference)
    for key in STORED:
        assert reference[key].shape == (gi_scenes.HEIGHT, gi_scenes.WIDTH, 3)
        assert np.isfinite(reference[key]).all() and reference[key].min() >= 0.0
    snapshot = take_snapshot(scene, bpy.context.evaluated_depsgraph_get())
    seen = primary_visibility(world_triangles(snapshot), snapshot.camera, gi_scenes.WIDTH,
                              gi_scenes.HEIGHT)
    agreement = (seen.hit == (reference["Alpha"] > 0.5)).mean()
    assert agreement > 0.99, agreement
    assert reference["Diffuse Indirect"][seen.hit].mean() > 0.0

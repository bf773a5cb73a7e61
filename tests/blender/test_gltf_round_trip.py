"""Imported material graphs (issue 22 point 3, acceptance (c); issue 18 point 2): a textured
metallic-roughness scene built here, exported by Blender's glTF exporter and imported back
(tests/blender/gltf_scenes.py), renders per texel — Base Color, Alpha, and Roughness / Metallic
through Image Texture → Separate Color as the importer builds them — against Cycles
(tests/data/gltf_refs, made by tools/make_gltf_references.py)."""
from __future__ import annotations

import json
import pathlib

import bpy
import gltf_scenes
import numpy as np

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "gltf_refs"
PASSES = ("Combined", "Diffuse Color", "Diffuse Direct", "Glossy Direct")


def relative_l1(ours, reference, mask=None):
    if mask is None:
        mask = np.ones(reference.shape[:2], bool)
    return float(np.abs(ours[mask] - reference[mask]).sum() /
                 max(np.abs(reference[mask]).sum(), 1e-12))


def build():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gltf_scenes.build("gltf_room", scene)
    return scene


def preview(scene, tracer="AUTO", width=gltf_scenes.WIDTH, height=gltf_scenes.HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}, lines


def test_the_importers_graphs_are_read_per_texel(voxgi):
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.scene.textures import PARAM_VARIANTS, variant_values

    build()
    # what the importer built: Image Texture → Separate Color → Roughness / Metallic
    floor_tree = bpy.data.materials["Floor"].node_tree
    assert any(n.type == "SEPARATE_COLOR" for n in floor_tree.nodes)
    snapshot = take_snapshot(bpy.context.scene)
    assert snapshot.warnings == ()  # no "uses its mean" any more
    by_name = {m.name: (i, m) for i, m in enumerate(snapshot.materials)}
    index, floor = by_name["Floor"]
    assert floor.base_color_texture >= 0 and floor.param_texture >= 0
    assert floor.param_variants == index + 1
    params = snapshot.textures[floor.param_texture].pixels
    pattern = gltf_scenes.metal_rough_pixels(bands=3, metal_share=0.3)
    np.testing.assert_allclose(params[..., 0], pattern[..., 1], atol=2.5e-3)  # G: roughness
    np.testing.assert_allclose(params[..., 1], pattern[..., 2], atol=2.5e-3)  # B: metallic
    variants = snapshot.materials[index + 1:index + 1 + PARAM_VARIANTS]
    rough, metal = variant_values(np.arange(PARAM_VARIANTS))
    np.testing.assert_allclose([m.roughness for m in variants], rough)
    np.testing.assert_allclose([m.metallic for m in variants], metal)
    assert all(m.base_color_texture == floor.base_color_texture for m in variants)
    _, fence = by_name["Fence"]
    assert fence.alpha_texture >= 0  # alpha survives the round trip


def test_gltf_round_trip_against_cycles(voxgi):
    scene = build()
    passes, lines = preview(scene)
    reference = np.load(REFS / "gltf_room.npz")
    limits = json.loads((REFS / "limits.json").read_text())["gltf_room"]
    mask = reference["Alpha"].astype(np.float64) > 0.5
    errors = {name: relative_l1(passes[name], reference[name].astype(np.float64), mask)
              for name in PASSES}
    print("glTF round trip vs Cycles:", {k: round(v, 4) for k, v in errors.items()})
    for name in PASSES:
        assert errors[name] <= limits[name], (name, errors, lines)


def test_numpy_and_gpu_agree_on_texel_parameters(voxgi):
    scene = build()
    gpu, _ = preview(scene, "AUTO", 80, 60)
    reference, _ = preview(scene, "NUMPY", 80, 60)
    for name in PASSES + ("Glossy Color",):
        error = relative_l1(gpu[name], reference[name])
        assert error < 0.02, (name, error)


def test_variant_materials_are_capped(voxgi, monkeypatch):
    """Each material with Roughness / Metallic per texel adds PARAM_VARIANTS rows to the GPU's
    materials texture; past MAX_VARIANT_MATERIALS the others take their images' means, with a
    warning (here the cap is lowered to one of the scene's two such materials)."""
    from voxgi.blender.snapshot import materials as snapshot_materials
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    monkeypatch.setattr(snapshot_materials, "MAX_VARIANT_MATERIALS", 1)
    snapshot = take_snapshot(bpy.context.scene)
    textured = [m for m in snapshot.materials if m.name in ("Floor", "Box")]
    assert sorted(m.param_texture >= 0 for m in textured) == [False, True]
    assert any("per texel" in w and "means" in w for w in snapshot.warnings), snapshot.warnings

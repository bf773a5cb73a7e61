"""Normal maps (issue 18 point 2, issue 22 point 3): a tangent-space Normal Map node fed by an
image perturbs the shading normal of what the camera sees as Cycles' node does, on the GPU as
in the numpy reference, against Cycles (tests/data/texture_refs/normal_mapped_room.npz, made
by tools/make_texture_references.py --scenes normal_mapped_room)."""
from __future__ import annotations

import json
import pathlib

import bpy
import numpy as np
import texture_scenes
from test_cutouts import relative_l1

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "texture_refs"
PASSES = ("Combined", "Diffuse Direct", "Glossy Direct")


def build():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    texture_scenes.build("normal_mapped_room", scene)
    return scene


def preview(scene, tracer="AUTO", width=texture_scenes.WIDTH, height=texture_scenes.HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}, lines


def test_the_snapshot_reads_the_normal_map(voxgi):
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    snapshot = take_snapshot(bpy.context.scene)
    assert snapshot.warnings == ()
    floor = next(m for m in snapshot.materials if m.name == "Checker Floor")
    assert floor.normal_texture >= 0 and floor.normal_strength == 1.0
    texture = snapshot.textures[floor.normal_texture]
    # Non-Color byte pixels as they are (8-bit rounding), through the floor's Mapping (3 × 2)
    np.testing.assert_allclose(texture.pixels[..., :3],
                               texture_scenes.tile_normal_pixels()[..., :3], atol=2.5e-3)
    np.testing.assert_allclose(texture.uv_transform, [[3, 0, 0], [0, 2, 0]], atol=1e-6)
    # a Bump node instead: left out, with a note
    tree = bpy.data.materials["Checker Floor"].node_tree
    bump = tree.nodes.new("ShaderNodeBump")
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    snapshot = take_snapshot(bpy.context.scene)
    floor = next(m for m in snapshot.materials if m.name == "Checker Floor")
    assert floor.normal_texture == -1
    assert any("Checker Floor" in w and "normal map out" in w for w in snapshot.warnings), \
        snapshot.warnings


def test_normal_mapped_floor_against_cycles(voxgi):
    scene = build()
    passes, lines = preview(scene)
    reference = np.load(REFS / "normal_mapped_room.npz")
    limits = json.loads((REFS / "limits.json").read_text())["normal_mapped_room"]
    mask = reference["Alpha"].astype(np.float64) > 0.5
    errors = {name: relative_l1(passes[name], reference[name].astype(np.float64), mask)
              for name in PASSES}
    print("normal-mapped room vs Cycles:", {k: round(v, 4) for k, v in errors.items()})
    for name in PASSES:
        assert errors[name] <= limits[name], (name, errors, lines)


def test_numpy_and_gpu_agree_on_normal_maps(voxgi):
    scene = build()
    gpu, _ = preview(scene, "AUTO", 80, 60)
    reference, _ = preview(scene, "NUMPY", 80, 60)
    for name in PASSES + ("Diffuse Indirect",):
        error = relative_l1(gpu[name], reference[name])
        assert error < 0.02, (name, error)

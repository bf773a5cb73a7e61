"""Small scene builders for the Blender tests (data API only, background-safe)."""
from __future__ import annotations

import bpy
import numpy as np


def link(obj, scene=None):
    """Link ``obj`` into the scene's master collection and return it."""
    (scene or bpy.context.scene).collection.objects.link(obj)
    return obj


def mesh_object(name, vertices, faces=(), edges=(), scene=None, data_name=None):
    """A new mesh object from vertex (N, 3) and face index lists, linked into the scene."""
    mesh = bpy.data.meshes.new(data_name or name)
    mesh.from_pydata(
        np.asarray(vertices, dtype=np.float64).reshape(-1, 3).tolist(),
        [list(e) for e in edges],
        [list(f) for f in faces],
    )
    mesh.update()
    return link(bpy.data.objects.new(name, mesh), scene)


def quad_object(name="Quad", size=1.0, scene=None):
    """A single square face of edge ``size`` in the XY plane, centred on the origin."""
    h = size / 2
    return mesh_object(name, [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [(0, 1, 2, 3)], scene=scene)


def principled(name, color, roughness=0.5, metallic=0.0, specular=0.5,
               emission=(0.0, 0.0, 0.0), emission_strength=0.0):
    """A material with a Principled BSDF set to these values (linear RGB)."""
    material = bpy.data.materials.new(name)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Specular IOR Level"].default_value = specular
    bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
    bsdf.inputs["Emission Strength"].default_value = emission_strength
    return material


def armature_object(name, bones, scene=None):
    """An armature object with ``bones``: (name, head, tail, parent name or None, deform) tuples."""
    from voxgi.operators.demo_scene import BoneSpec, add_bones  # importable once the add-on is

    scene = scene or bpy.context.scene
    obj = link(bpy.data.objects.new(name, bpy.data.armatures.new(name)), scene)
    add_bones(scene, obj, [BoneSpec(*bone) for bone in bones])
    return obj


def assign_weights(obj, group_names, weights):
    """Create vertex groups ``group_names`` on ``obj`` with ``weights`` (V, G); zero = not in the group.

    One ``VertexGroup.add`` call per (group, distinct weight): no per-vertex loop.
    """
    weights = np.asarray(weights, dtype=np.float64)
    for g, name in enumerate(group_names):
        group = obj.vertex_groups.new(name=name)
        column = weights[:, g]
        for value in np.unique(column[column > 0]):
            group.add(np.nonzero(column == value)[0].tolist(), float(value), "REPLACE")


def skinned_strip(scene=None, weights=None, extra_groups=("ctrl", "not_a_bone")):
    """A 4-vertex strip skinned to an armature with 6 deform bones and one non-deform bone 'ctrl'.

    Returns (mesh object, armature object, group names, weights (4, 6 + len(extra_groups))).
    The deform bones are 'B0'..'B5' along +X; 'ctrl' does not deform.
    """
    bones = [(f"B{i}", (i, 0, 0), (i + 0.9, 0, 0), f"B{i - 1}" if i else None, True) for i in range(6)]
    bones.insert(3, ("ctrl", (0, 1, 0), (0, 1, 1), None, False))
    rig = armature_object("Rig", bones, scene)
    strip = mesh_object("Strip", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], scene=scene)
    names = [f"B{i}" for i in range(6)] + list(extra_groups)
    if weights is None:
        weights = np.array([
            [0.9, 0.5, 0.4, 0.3, 0.2, 0.1, 1.0, 1.0],   # 6 deform influences -> top 4 kept
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.7, 0.0],   # one influence -> weight 1
            [0.2, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9],   # two equal influences
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0],   # only non-deform groups -> all zero
        ])[:, : len(names)]
    assign_weights(strip, names, weights)
    modifier = strip.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    return strip, rig, names, weights


def expected_top4(weights, bone_count):
    """Reference top-4 normalised weights per vertex as a list of {bone index: weight} dicts."""
    out = []
    for row in np.asarray(weights, dtype=np.float64)[:, :bone_count]:
        order = np.argsort(-row, kind="stable")[:4]
        kept = {int(i): row[i] for i in order if row[i] > 0}
        total = sum(kept.values())
        out.append({i: w / total for i, w in kept.items()})
    return out

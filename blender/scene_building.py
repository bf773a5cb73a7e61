"""bpy helpers that build scene content from data (background-safe), shared by the demo scene,
GFG import and the tests: Principled materials, mesh objects from arrays, armature bones."""
from __future__ import annotations

from contextlib import contextmanager
from typing import NamedTuple

import bpy
import numpy as np


def principled_material(name: str, color, roughness: float = 0.5, metallic: float = 0.0,
                        specular: float | None = None, emission=(0.0, 0.0, 0.0),
                        emission_strength: float = 0.0):
    """A new material whose Principled BSDF has this linear RGB base colour (and, when given,
    specular IOR level and emission)."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5.0 creates materials without nodes
        material.use_nodes = True
    material.diffuse_color = (*color, 1.0)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    if specular is not None:
        bsdf.inputs["Specular IOR Level"].default_value = specular
    if emission_strength:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission_strength
    return material


def mesh_object(name: str, vertices, faces=(), *, edges=(), collection=None, materials=(),
                face_materials=None, data_name: str | None = None):
    """A new mesh object from vertex (N, 3) and face/edge index lists, linked into
    ``collection`` (default: the context scene's master collection).

    face_materials : optional (F,) int slot index per face.
    """
    mesh = bpy.data.meshes.new(data_name or name)
    mesh.from_pydata(np.asarray(vertices, dtype=np.float64).reshape(-1, 3).tolist(),
                     [list(e) for e in edges], [list(f) for f in faces])
    for material in materials:
        mesh.materials.append(material)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


class BoneSpec(NamedTuple):
    """A bone to create: head/tail in armature space (metres), parent by name, roll in radians."""

    name: str
    head: tuple[float, float, float]
    tail: tuple[float, float, float]
    parent: str | None = None
    deform: bool = True
    connect: bool = False
    roll: float = 0.0


@contextmanager
def armature_edit_mode(scene, armature_obj, view_layer=None):
    """Edit mode on ``armature_obj`` for the duration of the block; yields its edit bones.

    Bones only exist in edit mode: this enters it through a context override on
    ``view_layer`` (default: the scene's first; background-safe), returns to object mode
    and restores the active object. Raises RuntimeError when Blender refuses the mode
    (linked or hidden armature).
    """
    view_layer = view_layer or scene.view_layers[0]
    previous = view_layer.objects.active
    view_layer.objects.active = armature_obj
    try:
        with bpy.context.temp_override(
            scene=scene, view_layer=view_layer, active_object=armature_obj, object=armature_obj
        ):
            bpy.ops.object.mode_set(mode="EDIT")
            try:
                yield armature_obj.data.edit_bones
            finally:
                bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        view_layer.objects.active = previous


def add_bones(scene, armature_obj, bones) -> None:
    """Create ``bones`` (``BoneSpec``, parents before children) in ``armature_obj``."""
    with armature_edit_mode(scene, armature_obj) as edit_bones:
        for spec in bones:
            bone = edit_bones.new(spec.name)
            bone.head, bone.tail, bone.use_deform = spec.head, spec.tail, spec.deform
            bone.roll = spec.roll
            if spec.parent is not None:
                bone.parent, bone.use_connect = edit_bones[spec.parent], spec.connect

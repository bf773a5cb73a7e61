"""Skinning data for the snapshot: armatures, rest shapes and top-4 bone weights (main thread).

Vertex groups of an evaluated mesh are not readable with ``foreach_get``, so for the
duration of a snapshot each skinned object gets a temporary Geometry Nodes modifier
(appended after the user's modifiers) that copies every deform-bone vertex group into
a float POINT attribute, and its Armature modifiers are switched off in the viewport
so the evaluated mesh is the REST shape with the other modifiers applied.
``temporary_weight_attributes`` undoes all of it on exit, whatever happened.
"""
from __future__ import annotations

from contextlib import contextmanager

import bpy
import numpy as np

from ...voxgi_addon.errors import VoxGIError
from ...voxgi_addon.scene.snapshot import ArmatureData, SkinData

MAX_INFLUENCES = 4
MAX_DEFORM_BONES = 256  # bone indices are uint8
WEIGHT_ATTRIBUTE_PREFIX = "__voxgi_weight_"
_TEMP_NAME = "VoxGI weights (temporary)"


def armature_modifiers(obj) -> list:
    """The object's Armature modifiers that deform it in the viewport (enabled, with an armature)."""
    return [
        mod for mod in obj.modifiers
        if mod.type == "ARMATURE" and mod.show_viewport
        and mod.object is not None and mod.object.type == "ARMATURE"
    ]


def deform_bone_names(armature_obj) -> tuple[str, ...]:
    """Names of the deform bones of an armature object, in ``Armature.bones`` order.

    Raises VoxGIError if there are more than ``MAX_DEFORM_BONES``.
    """
    names = tuple(b.name for b in armature_obj.data.bones if b.use_deform)
    if len(names) > MAX_DEFORM_BONES:
        raise VoxGIError(
            f"Armature '{armature_obj.name}' has {len(names)} deform bones; VoxGI supports at most "
            f"{MAX_DEFORM_BONES} (bone indices are 8-bit). Turn off Deform on helper bones."
        )
    return names


def _bone_matrices(collection, prop: str, count: int) -> np.ndarray:
    # foreach_get flattens Blender's column-major matrices: transpose to row-major.
    flat = np.empty(count * 16, dtype=np.float32)
    collection.foreach_get(prop, flat)
    return flat.reshape(count, 4, 4).transpose(0, 2, 1).astype(np.float64)


def read_armature(armature_obj, armature_eval) -> ArmatureData:
    """``ArmatureData`` of an armature object (deform bones only).

    armature_obj : the original object (bone hierarchy); armature_eval : its evaluated
    copy (pose and world matrix of the current frame). Parents are the nearest deform
    ancestor, -1 for none.
    """
    bones = armature_obj.data.bones
    names = deform_bone_names(armature_obj)
    index = {name: i for i, name in enumerate(names)}
    deform = np.array([b.use_deform for b in bones], dtype=bool)
    rest = _bone_matrices(bones, "matrix_local", len(bones))[deform]
    pose = _bone_matrices(armature_eval.pose.bones, "matrix", len(bones))[deform]
    parents = np.full(len(names), -1, dtype=np.int32)
    for i, name in enumerate(names):
        parent = bones[name].parent
        while parent is not None and parent.name not in index:
            parent = parent.parent
        if parent is not None:
            parents[i] = index[parent.name]
    return ArmatureData(
        name=armature_obj.name_full,
        bone_names=names,
        parents=parents,
        rest_matrices=rest,
        pose_matrices=pose,
        world_matrix=np.array(armature_eval.matrix_world, dtype=np.float64),
    )


def _weight_node_group(layers: list[tuple[str, str]]):
    """A geometry node group copying each vertex group ``src`` to a float POINT attribute ``dst``."""
    group = bpy.data.node_groups.new(_TEMP_NAME, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    geometry = nodes.new("NodeGroupInput").outputs[0]
    for src, dst in layers:
        read = nodes.new("GeometryNodeInputNamedAttribute")
        read.data_type = "FLOAT"
        read.inputs["Name"].default_value = src
        store = nodes.new("GeometryNodeStoreNamedAttribute")
        store.data_type = "FLOAT"
        store.domain = "POINT"
        store.inputs["Name"].default_value = dst
        links.new(geometry, store.inputs["Geometry"])
        links.new(read.outputs["Attribute"], store.inputs["Value"])
        geometry = store.outputs["Geometry"]
    links.new(geometry, nodes.new("NodeGroupOutput").inputs[0])
    return group


def weight_layers(obj, bone_names: tuple[str, ...]) -> list[tuple[int, str, str]]:
    """(bone index, vertex group name, attribute name) for each deform bone with a vertex group on ``obj``."""
    groups = obj.vertex_groups
    return [
        (i, name, f"{WEIGHT_ATTRIBUTE_PREFIX}{i}")
        for i, name in enumerate(bone_names) if groups.get(name) is not None
    ]


@contextmanager
def temporary_weight_attributes(skinned: dict, depsgraph):
    """Evaluate skinned objects in their rest shape with weight attributes, then restore them.

    skinned : {object: list of (bone index, vertex group, attribute) from ``weight_layers``}.
    Inside the block, ``depsgraph`` is re-evaluated: each object's evaluated mesh is its rest
    shape (Armature modifiers off, other modifiers on) carrying the float POINT attributes.
    On exit every change is undone in reverse order and the depsgraph re-evaluated.
    """
    undo = []
    try:
        for obj, layers in skinned.items():
            active = obj.modifiers.active
            if active is not None:  # adding a modifier makes it the active one
                undo.append(lambda o=obj, a=active: setattr(o.modifiers, "active", a))
            for mod in armature_modifiers(obj):
                mod.show_viewport = False
                undo.append(lambda m=mod: setattr(m, "show_viewport", True))
            if layers:
                group = _weight_node_group([(src, dst) for _, src, dst in layers])
                undo.append(lambda g=group: bpy.data.node_groups.remove(g))
                modifier = obj.modifiers.new(_TEMP_NAME, "NODES")
                undo.append(lambda o=obj, m=modifier: o.modifiers.remove(m))
                modifier.node_group = group
        if undo:
            depsgraph.update()
        yield
    finally:
        for restore in reversed(undo):
            restore()
        if undo:
            depsgraph.update()


def top_weights(mesh, layers: list[tuple[int, str, str]], armature_name: str) -> SkinData:
    """Top-4 normalised bone weights of an evaluated mesh carrying the weight attributes.

    Streams one bone at a time, keeping each row's 4 largest weights sorted in decreasing
    order, so memory is (V, 5) whatever the bone count; only rows whose new weight beats
    their current 4th are re-sorted. Ties keep the lower bone index. Rows with no positive
    weight stay all zero.
    Returns SkinData with weights (V, 4) float32 and bone_indices (V, 4) uint8.
    """
    count = len(mesh.vertices)
    weights = np.zeros((count, MAX_INFLUENCES), dtype=np.float32)
    indices = np.zeros((count, MAX_INFLUENCES), dtype=np.int32)
    values = np.empty(count, dtype=np.float32)
    for bone, _, attribute in layers:
        mesh.attributes[attribute].data.foreach_get("value", values)
        rows = np.nonzero(values > weights[:, -1])[0]  # NaN and non-positive never enter
        if rows.size == 0:
            continue
        cand_w = np.concatenate([weights[rows], values[rows, None]], axis=1)
        cand_i = np.concatenate([indices[rows], np.full((rows.size, 1), bone, np.int32)], axis=1)
        keep = np.argsort(-cand_w, axis=1, kind="stable")[:, :MAX_INFLUENCES]
        weights[rows] = np.take_along_axis(cand_w, keep, axis=1)
        indices[rows] = np.take_along_axis(cand_i, keep, axis=1)
    weights = np.where(np.isfinite(weights), weights, 0).astype(np.float32)
    totals = weights.sum(axis=1, keepdims=True)
    weights = np.divide(weights, totals, out=np.zeros_like(weights), where=totals > 0)
    indices[weights == 0] = 0
    return SkinData(weights=weights, bone_indices=indices.astype(np.uint8), armature=armature_name)

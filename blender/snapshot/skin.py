"""Skinning data for the snapshot: armatures, rest shapes and top-4 bone weights (main thread).

Vertex groups of an evaluated mesh are not readable with ``foreach_get``, so for the
duration of a snapshot each skinned object gets a temporary Geometry Nodes modifier, placed
just before its first Armature modifier, that stores the rest shape (positions per point,
normals per corner) and copies every deform-bone vertex group into a float POINT attribute.
The user's modifiers are never switched on or off, so the viewport, F12 and animation renders
(whose depsgraphs honour different visibility toggles) all read the same rest shape.
``temporary_weight_attributes`` undoes all of it on exit, whatever happened.
"""
from __future__ import annotations

from contextlib import contextmanager

import bpy
import numpy as np

from ...voxgi_addon.errors import VoxGIError
from ...voxgi_addon.scene.snapshot import ArmatureData, SkinData
from .mesh import read_corner_normals, read_positions

MAX_INFLUENCES = 4
MAX_DEFORM_BONES = 256  # bone indices are uint8
WEIGHT_ATTRIBUTE_PREFIX = "__voxgi_weight_"
REST_POSITION = "__voxgi_rest_position"  # POINT FLOAT_VECTOR: the shape before the Armature modifier
REST_NORMAL = "__voxgi_rest_normal"      # CORNER FLOAT_VECTOR: its corner normals
_TEMP_NAME = "VoxGI weights (temporary)"
_EVALUATING = [0]  # > 0 while the temporary modifiers are added, evaluated and removed


def evaluating_own_changes() -> bool:
    """Is the depsgraph being evaluated for the temporary modifiers of a snapshot (its updates
    are the snapshot's own, not the user's: ``blender/updates.py`` leaves them out)?"""
    return _EVALUATING[0] > 0


def is_temporary_group(name: str) -> bool:
    """Is ``name`` a node group the snapshot adds for a moment (``_skin_node_group``)?"""
    return name.startswith(_TEMP_NAME)


def modifier_enabled(modifier, depsgraph=None) -> bool:
    """Whether ``modifier`` runs in ``depsgraph``'s evaluation: its Render toggle in a render
    depsgraph (F12, animation renders), its Viewport toggle otherwise (no depsgraph: viewport)."""
    if depsgraph is not None and depsgraph.mode == "RENDER":
        return modifier.show_render
    return modifier.show_viewport


def armature_modifiers(obj, depsgraph=None) -> list:
    """The object's Armature modifiers that deform it in ``depsgraph``'s evaluation mode
    (``modifier_enabled``, with an armature object)."""
    return [
        mod for mod in obj.modifiers
        if mod.type == "ARMATURE" and modifier_enabled(mod, depsgraph)
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


def _skin_node_group(layers: list[tuple[str, str]]):
    """A geometry node group storing the incoming shape (``REST_POSITION`` per point,
    ``REST_NORMAL`` per face corner) and copying each vertex group ``src`` to a float POINT
    attribute ``dst``. Placed before the Armature modifier, it records the rest shape; the
    attributes ride through the deformation unchanged."""
    group = bpy.data.node_groups.new(_TEMP_NAME, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    geometry = nodes.new("NodeGroupInput").outputs[0]

    def store(data_type, domain, name, value):
        nonlocal geometry
        node = nodes.new("GeometryNodeStoreNamedAttribute")
        node.data_type, node.domain = data_type, domain
        node.inputs["Name"].default_value = name
        links.new(geometry, node.inputs["Geometry"])
        links.new(value, node.inputs["Value"])
        geometry = node.outputs["Geometry"]

    store("FLOAT_VECTOR", "POINT", REST_POSITION, nodes.new("GeometryNodeInputPosition").outputs[0])
    store("FLOAT_VECTOR", "CORNER", REST_NORMAL, nodes.new("GeometryNodeInputNormal").outputs[0])
    for src, dst in layers:
        read = nodes.new("GeometryNodeInputNamedAttribute")
        read.data_type = "FLOAT"
        read.inputs["Name"].default_value = src
        store("FLOAT", "POINT", dst, read.outputs["Attribute"])
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
    """Evaluate skinned objects with their rest shape and weights as attributes, then restore them.

    skinned : {object: list of (bone index, vertex group, attribute) from ``weight_layers``}.
    Inside the block, ``depsgraph`` is re-evaluated: each object's evaluated mesh is posed as
    that depsgraph poses it and carries ``REST_POSITION`` / ``REST_NORMAL`` (its shape just
    before its first Armature modifier, every modifier before that applied, every one after
    it applied to the attributes; read them with ``rest_positions`` / ``rest_corner_normals``)
    and the float POINT weight attributes. The user's modifiers are never switched: one
    temporary Geometry Nodes modifier goes in front of the Armature modifier, so the result is
    the same whichever visibility toggle the depsgraph honours (F12 renders with
    ``show_render``, the viewport with ``show_viewport``). On exit every change is undone in
    reverse order, whatever happened, and the depsgraph re-evaluated.
    """
    undo = []
    _EVALUATING[0] += 1
    try:
        for obj, layers in skinned.items():
            active = obj.modifiers.active
            if active is not None:  # adding a modifier makes it the active one
                undo.append(lambda o=obj, a=active: setattr(o.modifiers, "active", a))
            group = _skin_node_group([(src, dst) for _, src, dst in layers])
            undo.append(lambda g=group: bpy.data.node_groups.remove(g))
            first = next((i for i, m in enumerate(obj.modifiers) if m.type == "ARMATURE"), None)
            modifier = obj.modifiers.new(_TEMP_NAME, "NODES")
            undo.append(lambda o=obj, m=modifier: o.modifiers.remove(m))
            modifier.node_group = group
            modifier.show_viewport = modifier.show_render = True
            if first is not None:
                obj.modifiers.move(len(obj.modifiers) - 1, first)
        if undo:
            depsgraph.update()
        yield
    finally:
        try:
            for restore in reversed(undo):
                restore()
            if undo:
                depsgraph.update()
        finally:
            _EVALUATING[0] -= 1


def rest_positions(mesh) -> np.ndarray:
    """(V, 3) float32 rest positions of an evaluated mesh read inside
    ``temporary_weight_attributes`` (its own positions when it carries none)."""
    if REST_POSITION not in mesh.attributes:
        return read_positions(mesh)
    values = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.attributes[REST_POSITION].data.foreach_get("vector", values)
    return values.reshape(-1, 3)


def rest_corner_normals(mesh, corners: np.ndarray) -> np.ndarray:
    """(T, 3, 3) float32 rest-shape corner normals at ``corners`` (``rest_positions``'s
    counterpart; the mesh's own corner normals when it carries none)."""
    if REST_NORMAL not in mesh.attributes:
        return read_corner_normals(mesh, corners)
    values = np.empty(len(mesh.loops) * 3, dtype=np.float32)
    mesh.attributes[REST_NORMAL].data.foreach_get("vector", values)
    normals = values.reshape(-1, 3)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    return normals[corners]


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

"""Depsgraph updates as plain records, and cheap snapshots for transform-only changes
(main thread only).

``records_from_depsgraph`` turns ``depsgraph.updates`` into ``UpdateRecord``s for the planner
(``voxgi_addon/scene/changes.py``). Hiding or unhiding an object reaches the depsgraph as a
bare Scene update, so the set of visible mesh objects is compared with the last snapshot's and
a synthetic VISIBILITY record is added when it differs.

``scene_index`` describes the last snapshot for the planner: which object uses which cache key,
mesh datablock, materials and armature.

``transform_snapshot`` re-reads only matrices, poses, lights, camera and world and keeps the
previous snapshot's meshes and materials (same objects), which is all a transform-only plan
needs and touches nothing in the scene (a full snapshot of a skinned mesh adds and removes
a temporary modifier: see ``snapshot/skin.py``). It returns None when the visible mesh
objects differ from the previous snapshot's, and the caller takes a full snapshot.
"""
from __future__ import annotations

import dataclasses

import bpy
import numpy as np

from ..voxgi_addon.scene.changes import ObjectEntry, SceneIndex, UpdateRecord
from .snapshot.environment import read_camera, read_light, read_world
from .snapshot.scene import RENDERABLE, object_kind, renders
from .snapshot.skin import read_armature

VISIBILITY_RECORD = UpdateRecord("VISIBILITY", "visible objects", geometry=True)


def id_type(id_data) -> str:
    """The planner's ID type name of a datablock (``changes.ID_TYPES``)."""
    for cls, name in ((bpy.types.Object, "OBJECT"), (bpy.types.Mesh, "MESH"),
                      (bpy.types.Material, "MATERIAL"), (bpy.types.Light, "LIGHT"),
                      (bpy.types.Armature, "ARMATURE"), (bpy.types.World, "WORLD"),
                      (bpy.types.Scene, "SCENE"), (bpy.types.Collection, "COLLECTION"),
                      (bpy.types.Camera, "CAMERA"), (bpy.types.NodeTree, "NODETREE")):
        if isinstance(id_data, cls):
            return name
    return "OTHER"


def visible_mesh_names(view_layer) -> set[str]:
    """Names of the objects a full snapshot reads from the view layer (instances aside)."""
    return {o.name_full for o in view_layer.objects
            if o.type in RENDERABLE and renders(o, view_layer)}


def records_from_depsgraph(depsgraph, index: SceneIndex | None = None) -> list[UpdateRecord]:
    """The depsgraph's pending updates as records (+ a visibility record, see module doc)."""
    records = []
    for update in depsgraph.updates:
        data = update.id
        kind = id_type(data)
        original = getattr(data, "original", data) or data
        records.append(UpdateRecord(
            kind, original.name_full, bool(update.is_updated_transform),
            bool(update.is_updated_geometry), bool(update.is_updated_shading),
            original.type if kind == "OBJECT" else ""))
    if index is not None and visible_mesh_names(depsgraph.view_layer) != set(index.objects):
        records.append(VISIBILITY_RECORD)
    return records


def scene_index(snapshot, view_layer) -> SceneIndex:
    """Who uses what in ``snapshot`` (taken from ``view_layer`` just now)."""
    objects = {}
    for obj in snapshot.objects:
        blender_object = bpy.data.objects.get(obj.name)
        if blender_object is None:
            continue
        materials = tuple(s.material.name_full for s in blender_object.material_slots
                          if s.material is not None)
        armature = None if obj.armature is None else bpy.data.objects.get(obj.armature)
        objects[obj.name] = ObjectEntry(
            obj.mesh, blender_object.data.name_full, materials, obj.kind, obj.armature,
            None if armature is None else armature.data.name_full)
    lights = [bpy.data.objects.get(light.name) for light in snapshot.lights]
    return SceneIndex(objects, frozenset(light.name for light in snapshot.lights),
                      frozenset(o.data.name_full for o in lights if o is not None))


def transform_snapshot(previous, scene, depsgraph):
    """``previous`` with this frame's matrices, poses, lights and camera, or None when the
    visible mesh objects (or their kinds) changed since it was taken."""
    view_layer = depsgraph.view_layer
    if visible_mesh_names(view_layer) != {o.name for o in previous.objects}:
        return None
    objects, armatures = [], {}
    for obj in previous.objects:
        blender_object = bpy.data.objects[obj.name]
        kind, armature = object_kind(blender_object, depsgraph)
        if kind != obj.kind or (armature.name_full if armature else None) != obj.armature:
            return None
        evaluated = blender_object.evaluated_get(depsgraph)
        objects.append(dataclasses.replace(
            obj, world_matrix=np.array(evaluated.matrix_world, dtype=np.float64)))
        if armature is not None and armature.name_full not in armatures:
            armatures[armature.name_full] = read_armature(armature, armature.evaluated_get(depsgraph))
    lights = []
    for obj in view_layer.objects:
        if obj.type == "LIGHT" and obj.visible_get(view_layer=view_layer):
            light = read_light(obj, obj.evaluated_get(depsgraph))
            if light is not None:
                lights.append(light)
    notes: list[str] = []
    world = read_world(scene, notes)  # what it cannot read is said, once
    return dataclasses.replace(previous, objects=objects, armatures=armatures, lights=lights,
                               camera=read_camera(scene, depsgraph), world=world,
                               frame=int(scene.frame_current),
                               warnings=tuple(dict.fromkeys((*previous.warnings, *notes))))


def skin_state(obj, depsgraph) -> tuple[bytes, bytes]:
    """(rest shape, pose) fingerprints of a skinned mesh object: its base mesh's vertices and
    faces, and its armature's pose and both objects' matrices."""
    import hashlib

    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    rest = hashlib.blake2b(co.tobytes(), digest_size=16)
    rest.update(f"{len(mesh.polygons)}:{len(mesh.loops)}".encode())
    pose = hashlib.blake2b(np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64).tobytes(),
                           digest_size=16)
    for modifier in obj.modifiers:
        if modifier.type == "ARMATURE" and modifier.object is not None:
            armature = modifier.object.evaluated_get(depsgraph)
            bones = armature.pose.bones if armature.pose is not None else ()
            matrices = np.empty(len(bones) * 16, np.float32)
            if len(bones):
                bones.foreach_get("matrix", matrices)
            pose.update(matrices.tobytes())
            pose.update(np.array(armature.matrix_world, np.float64).tobytes())
    return rest.digest(), pose.digest()


def skin_states(snapshot, depsgraph) -> dict[str, tuple[bytes, bytes]]:
    """``skin_state`` of every skinned object of the snapshot, by object name."""
    out = {}
    for obj in snapshot.objects:
        if obj.kind == "skinned" and obj.name in bpy.data.objects:
            out[obj.name] = skin_state(bpy.data.objects[obj.name], depsgraph)
    return out


def without_skin_echo(records, states: dict[str, tuple[bytes, bytes]], depsgraph) -> list:
    """``records`` with geometry updates of skinned objects (and their meshes) checked against
    ``states``: an unchanged rest shape and pose drops the record (a snapshot's own temporary
    modifier, ``snapshot/skin.py``, re-evaluates the mesh); an unchanged rest shape with a new
    pose becomes a transform record; a new rest shape is a real edit and stays."""
    if not states:
        return list(records)
    mesh_owner = {bpy.data.objects[name].data.name_full: name for name in states
                  if name in bpy.data.objects}
    out = []
    for r in records:
        name = r.name if r.id_type == "OBJECT" else mesh_owner.get(r.name) \
            if r.id_type == "MESH" else None
        if name not in states or not r.geometry or name not in bpy.data.objects:
            out.append(r)
            continue
        rest, pose = skin_state(bpy.data.objects[name], depsgraph)
        if rest != states[name][0]:
            out.append(r)
        elif pose != states[name][1]:
            out.append(UpdateRecord("OBJECT", name, transform=True, object_type="MESH"))
    return out

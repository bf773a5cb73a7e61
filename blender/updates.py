"""Depsgraph updates as plain records, what changed since a snapshot, and posed snapshots
(main thread only).

``records_from_depsgraph`` turns ``depsgraph.updates`` into ``UpdateRecord``s for the planner
(``voxgi_addon/scene/changes.py``). Hiding or unhiding an object reaches the depsgraph as a
bare Scene update, so the set of visible mesh objects is compared with the last snapshot's and
a synthetic VISIBILITY record is added when it differs.

``scene_index`` describes the last snapshot for the planner: which object uses which cache key,
mesh datablock, materials and armature.

``transform_snapshot`` is ``snapshot/pose.posed_snapshot``: the previous snapshot with this
frame's matrices, poses, lights and camera, which is all a transform-only plan needs; it
evaluates no mesh, reads no material and touches nothing in the scene (a full snapshot of a
skinned mesh adds and removes a temporary modifier: see ``snapshot/skin.py``).

**What changed since a snapshot** (docs/gi_pipeline.md "Posed updates"): the viewport gets
the depsgraph's updates in ``view_update``; operators do not, so ``remember`` keeps the last
snapshot taken of each scene (``snapshot_or_error``) and two handlers log the updates of its
view layer's depsgraph from then on (``depsgraph_update_post``, and ``frame_change_post``,
which a frame change runs instead). ``posed_since`` plans them (``plan_updates``) and returns
the posed snapshot when no mesh, modifier, material, node group, image or visibility changed,
else None: the caller takes a full snapshot. The updates a snapshot causes itself (its
temporary modifiers) are not logged; a file load, undo and redo forget every snapshot.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..registration import add_handlers, remove_handlers
from ..voxgi_addon.scene.changes import ObjectEntry, SceneIndex, UpdateRecord, plan_updates
from .snapshot.pose import posed_snapshot, slot_materials
from .snapshot.scene import RENDERABLE, render_disabled, renders
from .snapshot.skin import evaluating_own_changes, is_temporary_group
from .snapshot.world_map import world_objects

VISIBILITY_RECORD = UpdateRecord("VISIBILITY", "visible objects", geometry=True)
MAX_LOGGED = 4096  # updates logged since a snapshot; past that the next one is a full snapshot


def id_type(id_data) -> str:
    """The planner's ID type name of a datablock (``changes.ID_TYPES``)."""
    for cls, name in ((bpy.types.Object, "OBJECT"), (bpy.types.Mesh, "MESH"),
                      (bpy.types.Material, "MATERIAL"), (bpy.types.Light, "LIGHT"),
                      (bpy.types.Armature, "ARMATURE"), (bpy.types.World, "WORLD"),
                      (bpy.types.Scene, "SCENE"), (bpy.types.Collection, "COLLECTION"),
                      (bpy.types.Camera, "CAMERA"), (bpy.types.NodeTree, "NODETREE"),
                      (bpy.types.Image, "IMAGE"), (bpy.types.Action, "ACTION"),
                      (bpy.types.Key, "KEY")):
        if isinstance(id_data, cls):
            return name
    return "OTHER"


def visible_mesh_names(view_layer) -> set[str]:
    """Names of the objects a full snapshot reads from the view layer (instances aside)."""
    disabled = render_disabled()
    return {o.name_full for o in view_layer.objects
            if o.type in RENDERABLE and renders(o, view_layer, disabled)}


def records_from_depsgraph(depsgraph, index: SceneIndex | None = None) -> list[UpdateRecord]:
    """The depsgraph's pending updates as records (+ a visibility record, see module doc).
    A material's, light's or world's own node tree is left out (its owner has a record), and
    so are the snapshot's temporary node groups."""
    records = []
    for update in depsgraph.updates:
        data = update.id
        kind = id_type(data)
        original = getattr(data, "original", data) or data
        if kind == "NODETREE" and (original.is_embedded_data or
                                   is_temporary_group(original.name_full)):
            continue
        records.append(UpdateRecord(
            kind, original.name_full, bool(update.is_updated_transform),
            bool(update.is_updated_geometry), bool(update.is_updated_shading),
            original.type if kind == "OBJECT" else "",
            tuple(original.color) if kind == "OBJECT" else None))
    if index is not None and visible_mesh_names(depsgraph.view_layer) != (
            set(index.objects) if index.visible is None else index.visible):
        records.append(VISIBILITY_RECORD)
    return records


def _animated(id_data) -> bool:
    data = None if id_data is None else id_data.animation_data
    return data is not None and (data.action is not None or len(data.drivers) > 0
                                 or len(data.nla_tracks) > 0)


def rest_animated(obj) -> bool:
    """Can a frame change alter a skinned object's rest shape: are the object (its modifiers'
    settings), its mesh or its shape keys animated or driven? Its geometry updates are then
    not only poses (``changes.ObjectEntry.rest_animated``)."""
    mesh = obj.data
    keys = getattr(mesh, "shape_keys", None)
    return _animated(obj) or _animated(mesh) or _animated(keys)


def reads_object_info(obj) -> bool:
    """Does a material of ``obj`` read Object Info (its Color, through a per-object variant or
    a bake keyed by it: an edit of the object's Color changes what it shows)?"""
    return any(slot.material is not None and slot.material.node_tree is not None and
               _has_object_info(slot.material.node_tree) for slot in obj.material_slots)


def _has_object_info(tree, depth: int = 0) -> bool:
    return depth < 16 and any(
        node.type == "OBJECT_INFO" or node.type == "GROUP" and node.node_tree is not None and
        _has_object_info(node.node_tree, depth + 1) for node in tree.nodes)


def scene_index(snapshot, view_layer) -> SceneIndex:
    """Who uses what in ``snapshot`` (taken from ``view_layer`` just now)."""
    objects = {}
    for obj in snapshot.objects:
        blender_object = bpy.data.objects.get(obj.name)
        if blender_object is None:
            continue
        armature = None if obj.armature is None else bpy.data.objects.get(obj.armature)
        objects[obj.name] = ObjectEntry(
            obj.mesh, blender_object.data.name_full, slot_materials(blender_object), obj.kind,
            obj.armature, None if armature is None else armature.data.name_full,
            obj.kind == "skinned" and rest_animated(blender_object),
            tuple(blender_object.color) if reads_object_info(blender_object) else None)
    lights = [bpy.data.objects.get(light.name) for light in snapshot.lights]
    # faceless objects (edges, points, an empty curve) are in no snapshot but are visible: kept
    # apart, else every later update would look like an object shown (a full snapshot)
    return SceneIndex(objects, frozenset(light.name for light in snapshot.lights),
                      frozenset(o.data.name_full for o in lights if o is not None),
                      frozenset(visible_mesh_names(view_layer)))


def transform_snapshot(previous, scene, depsgraph, world: bool = True, bakes=None):
    """``previous`` with this frame's matrices, poses, lights and camera (and world, unless
    ``world`` is False), or None when the visible mesh objects (or their kinds) changed since
    it was taken (``snapshot/pose.posed_snapshot``). bakes : the live viewport's queue
    (``snapshot.bakes.BakeQueue``), whose children bake a node-built world."""
    return posed_snapshot(previous, scene, depsgraph, world=world, bakes=bakes)


def world_state(scene) -> tuple:
    """(the scene's world's name, the objects its nodes read): a posed snapshot reads the
    world again when either changed, or one of those objects moved."""
    world = scene.world
    return (None if world is None else world.name_full, world_objects(world))


def world_touched(records, scene, before: tuple | None) -> bool:
    """Do ``records`` (or a new world, ``before`` being the last ``world_state``) change the
    world a snapshot reads?"""
    state = world_state(scene)
    return state != before or any(
        r.id_type == "WORLD" or (r.id_type == "OBJECT" and r.name in state[1]) for r in records)


# ---------------------------------------------------------------------------------------------
# what changed since the last snapshot of each scene (operators)


@dataclass(eq=False)
class _Watch:
    """The last snapshot of a scene's view layer and the updates logged since."""

    view_layer: str
    snapshot: object
    index: SceneIndex
    world: tuple
    records: list = field(default_factory=list)
    overflow: bool = False


_watched: dict[str, _Watch] = {}


def remember(snapshot, scene, depsgraph) -> None:
    """Keep ``snapshot`` (just taken from the viewport-mode ``depsgraph``) as the scene's last
    one and log the depsgraph's updates from now on (``posed_since``)."""
    if depsgraph.mode == "RENDER":  # F12 evaluates other modifiers: not the view layer's state
        return
    _watched[scene.name_full] = _Watch(depsgraph.view_layer.name, snapshot,
                                       scene_index(snapshot, depsgraph.view_layer),
                                       world_state(scene))


def remembered_index(scene, snapshot) -> SceneIndex | None:
    """The ``scene_index`` ``remember`` took of ``snapshot`` (the scene's last one), or None."""
    watch = _watched.get(scene.name_full)
    return watch.index if watch is not None and watch.snapshot is snapshot else None


def forget() -> None:
    """Forget every scene's last snapshot (file load, undo, redo, unregister)."""
    _watched.clear()


def posed_since(scene, depsgraph):
    """The scene's last snapshot posed at the depsgraph's frame (``posed_snapshot``) when the
    updates logged since it was taken change only matrices, poses, lights, camera or world;
    else None (a full snapshot is needed). The logged updates are consumed."""
    watch = _watched.get(scene.name_full)
    if watch is None or watch.view_layer != depsgraph.view_layer.name or depsgraph.mode == "RENDER":
        return None
    records, watch.records = watch.records, []
    if watch.overflow:
        watch.overflow = False
        return None
    plan = plan_updates(records, watch.index)
    if plan.full_snapshot or plan.rescan:
        return None
    return posed_snapshot(watch.snapshot, scene, depsgraph,
                          {name: e.materials for name, e in watch.index.objects.items()},
                          world_touched(records, scene, watch.world))


@bpy.app.handlers.persistent
def _log_updates(scene, depsgraph) -> None:
    """``depsgraph_update_post`` / ``frame_change_post``: log the watched view layer's updates
    (not those of a snapshot's own temporary modifiers)."""
    watch = _watched.get(scene.name_full)
    if watch is None or depsgraph is None or evaluating_own_changes() or \
            depsgraph.mode == "RENDER" or depsgraph.view_layer.name != watch.view_layer:
        return
    watch.records.extend(records_from_depsgraph(depsgraph))
    if len(watch.records) > MAX_LOGGED:
        watch.records.clear()
        watch.overflow = True


@bpy.app.handlers.persistent
def _forget_on_load(*_args) -> None:
    forget()


# an undo or redo step may bring back anything: the snapshot is forgotten before it
HANDLERS = (("depsgraph_update_post", _log_updates), ("frame_change_post", _log_updates),
            ("load_post", _forget_on_load), ("undo_pre", _forget_on_load),
            ("redo_pre", _forget_on_load))
classes = ()


def register() -> None:
    add_handlers(HANDLERS)


def unregister() -> None:
    remove_handlers(HANDLERS)
    forget()


# ---------------------------------------------------------------------------------------------
# the viewport's skinned objects: their own updates told from edits


_UNREAD = frozenset({"rna_type", "is_active", "show_expanded", "is_override_data", "persistent_uid",
                     "execution_time"})


def modifier_key(obj) -> tuple:
    """The object's modifier stack as plain values: each modifier's type, name and settings
    (an ID by its name; Geometry Nodes' inputs, which are ID properties, by their repr)."""
    out = []
    for modifier in obj.modifiers:
        values = []
        for prop in modifier.bl_rna.properties:
            if prop.identifier in _UNREAD or prop.type == "COLLECTION":
                continue
            value = getattr(modifier, prop.identifier, None)
            if isinstance(value, bpy.types.ID):
                value = value.name_full
            elif isinstance(value, bpy.types.bpy_struct):
                continue
            elif not isinstance(value, str) and hasattr(value, "__len__"):
                value = tuple(value)
            values.append((prop.identifier, value))
        inputs = () if modifier.type != "NODES" else \
            tuple((k, repr(modifier[k])) for k in modifier.keys())
        out.append((modifier.type, tuple(values), inputs))
    return tuple(out)


def skin_state(obj, depsgraph) -> tuple[bytes, bytes]:
    """(rest shape, pose) fingerprints of a skinned mesh object: its base mesh's vertices and
    faces and its modifier stack (``modifier_key``), and its armature's pose and both objects'
    matrices."""
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    rest = hashlib.blake2b(co.tobytes(), digest_size=16)
    rest.update(f"{len(mesh.polygons)}:{len(mesh.loops)}".encode())
    rest.update(repr(modifier_key(obj)).encode())
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

"""A posed snapshot: the last snapshot with this frame's matrices (main thread only).

A pose is bone matrices: skinning the cached voxels needs the armatures' pose and the
objects' matrices, nothing of the meshes' rest shapes, materials or world
(docs/gi_pipeline.md "Posed updates"). ``posed_snapshot`` re-reads only what moves — object
matrices, ray visibility and holdouts, the deforming armatures' bones, lights, the camera, a
few scene settings and, when asked, the world — and keeps the previous snapshot's meshes,
materials, textures and warnings. It evaluates no mesh (no ``to_mesh``), reads no material
and adds nothing to the scene (a full snapshot of a skinned mesh adds a temporary modifier:
``skin.py``), so it costs milliseconds where a full snapshot costs the meshes' and
materials' reading.

It is only right when nothing but matrices, poses, lights, camera or world changed since
``previous`` was taken: the callers know that from the depsgraph's updates
(``blender/updates.py``). It still checks what it cheaply can — the same visible objects with
the same mesh keys, kinds, armatures and slot materials — and returns None when they differ
(the caller then takes a full snapshot).
"""
from __future__ import annotations

import dataclasses

from .environment import read_camera, read_world
from .scene import (
    _visible_mesh_entries,
    instance_objects,
    mesh_objects,
    object_inputs,
    read_armatures,
    read_lights,
    scene_flags,
)

__all__ = ["posed_snapshot", "slot_materials"]


def slot_materials(obj) -> tuple[str, ...]:
    """Names of the materials in an object's slots (its own or its mesh's), in slot order."""
    return tuple(s.material.name_full for s in obj.material_slots if s.material is not None)


def posed_snapshot(previous, scene, depsgraph, materials: dict | None = None,
                   world: bool = False, bakes=None):
    """``previous`` (a ``SceneSnapshot`` of the same view layer) at the depsgraph's frame, or
    None when its objects no longer match (see the module doc).

    materials : object name → ``slot_materials`` when ``previous`` was taken (an object's
        slots relinked to other materials is then caught); None skips that check.
    world : read the world again (it changed, or a mapping object of it moved); else the
        previous one is kept.
    bakes : the live viewport's queue (``bakes.BakeQueue``): a node-built world is baked by
        its children (``world_process``), as in ``take_snapshot``.
    """
    entries = _visible_mesh_entries(depsgraph.view_layer, [], depsgraph)  # warned before
    entries = [e for e in entries if e.key in previous.meshes]
    # (each instance's Object Info only where a material reads its Color: checked below)
    given: list | None = [] if previous.object_colors else None
    instances = instance_objects(depsgraph, inputs=given)
    given = [g for o, g in zip(instances, given or ()) if o.mesh in previous.meshes]
    instances = [o for o in instances if o.mesh in previous.meshes]
    objects = mesh_objects(entries, depsgraph) + instances
    before = [(o.name, o.mesh, o.kind, o.armature) for o in previous.objects]
    if [(o.name, o.mesh, o.kind, o.armature) for o in objects] != before:
        return None  # objects added, removed, re-keyed or of another kind: read them
    if materials is not None and any(slot_materials(e.obj) != materials.get(e.obj.name_full)
                                     for e in entries):
        return None
    # each object's materials by its Object Info (``scene.with_object_materials``): its name
    # and instance are the previous ones, so its Random is too; its Color may have changed
    if previous.object_colors and tuple(
            g.color for g in [object_inputs(e.obj, depsgraph) for e in entries] + given) != \
            previous.object_colors:
        return None
    objects = [dataclasses.replace(o, materials=p.materials) if p.materials else o
               for o, p in zip(objects, previous.objects)]
    notes: list[str] = []
    world_data = previous.world if not world else read_world(
        scene, notes, deferred=None if bakes is None else bakes.worlds, depsgraph=depsgraph)
    return dataclasses.replace(
        previous, objects=objects, armatures=read_armatures(entries, depsgraph),
        lights=read_lights(depsgraph), camera=read_camera(scene, depsgraph), world=world_data,
        frame=int(scene.frame_current), **scene_flags(scene),
        warnings=tuple(dict.fromkeys((*previous.warnings, *notes))))

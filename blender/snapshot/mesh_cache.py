"""The live viewport's mesh reads kept between snapshots (main thread only).

A full snapshot reads every visible mesh's evaluated geometry with ``foreach_get``: positions,
Blender's loop triangles, material slots, the UV map and the corner normals (on a 142k-triangle
diorama 25–40 ms of a snapshot's 30–45). A material, an added object or a hidden one changes
none of them, yet needed a full snapshot. ``MeshReads`` keeps each mesh key's arrays (plain
numpy, never a bpy object) with the ``change_key`` it was read at; the next snapshot reuses
them when

- the depsgraph reported no geometry update of the object, its mesh datablock, or anything
  that may feed a modifier (``forget_updated``: a Key re-reads its mesh; a node group, an
  image, a texture … every object with modifiers or shape keys) since they were read — the
  updates Cycles re-syncs a mesh on;
- the object and its mesh are the same datablocks (``ID.session_uid``) under the same names,
  the evaluated mesh has the same numbers of vertices, corners and faces and the same active
  and render UV maps (``change_key``);
- it is a mesh object of the last snapshot read as the same key (an added or shown object is
  read), or one read ahead of the next snapshot since (``scene.read_ahead``: a full snapshot's
  reads spread over the view's draws), not skinned (a skinned mesh's rest shape is read through temporary modifiers:
  ``skin.py``), not a curve, text or metaball and not one an instancer makes of its own
  (``(instanced)`` keys).

Anything else is read again; ``clear`` forgets everything (the first update, undo / redo, a new
render engine: updates not seen by this one may have happened). Only the viewport
(``viewport_session.LiveGI``) keeps one: it sees every depsgraph update while Rendered mode
is on. F12 and the operators take full snapshots (docs/gi_pipeline.md "Snapshots that read
only what changed").
"""
from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from .materials import _digest

__all__ = ["MeshArrays", "MeshReads", "change_key"]

# ID types whose geometry updates may change an object's evaluated mesh through its modifiers
# (node groups, images and textures of displacement, shape keys, curves of a Curve modifier …):
# the ones below cannot, every other one re-reads the objects with modifiers
_NOT_MODIFIER_INPUTS = frozenset({"OBJECT", "MESH", "LIGHT", "CAMERA", "WORLD", "SCENE",
                                  "COLLECTION", "MATERIAL", "VISIBILITY"})


@dataclass(frozen=True)
class MeshArrays:
    """One mesh key's reads (``scene._read_mesh``): what its evaluated geometry alone gives.

    change : ``change_key`` when read; object / data : the object's and mesh datablock's
    ``name_full``; modified : the object has modifiers or its mesh shape keys (its evaluated
    mesh depends on more than its datablock)."""

    change: tuple
    object: str
    data: str
    modified: bool
    positions: np.ndarray
    triangles: np.ndarray
    corners: np.ndarray
    slots: np.ndarray
    uvs: np.ndarray | None
    corner_normals: np.ndarray
    used_slots: np.ndarray  # np.unique(slots): the slots the triangles use

    @functools.cached_property
    def digest(self) -> str:
        """The content key of positions, triangles, slots and UVs: what a material's bake over
        this mesh depends on besides its nodes (``materials.Surface``); hashed only when a
        bake asks (5 ms of a full snapshot of the diorama, which bakes nothing)."""
        return _digest(*(None if a is None else
                         hashlib.blake2b(a.tobytes(), digest_size=16).hexdigest()
                         for a in (self.positions, self.triangles, self.slots, self.uvs)))


def change_key(original, obj_eval) -> tuple | None:
    """What of a mesh object is cheap to compare and tells a different mesh: the object's and
    its mesh datablock's identity and names, the evaluated mesh's sizes and UV maps, edit mode.
    None for what is never kept (not a mesh object)."""
    if obj_eval.type != "MESH" or original.type != "MESH" or obj_eval.data is None:
        return None
    mesh, data = obj_eval.data, original.data
    layers = mesh.uv_layers
    render = next((layer.name for layer in layers if layer.active_render), None)
    active = layers.active.name if layers.active is not None else None
    return (original.session_uid, original.name_full, data.session_uid, data.name_full,
            len(mesh.vertices), len(mesh.loops), len(mesh.polygons), render, active,
            bool(original.mode == "EDIT"))


class MeshReads:
    """Mesh keys' ``MeshArrays`` from the last snapshot (see the module doc)."""

    def __init__(self):
        self._kept: dict[str, MeshArrays] = {}
        self._next: dict[str, MeshArrays] | None = None
        # key → (arrays, slot lookup, triangle materials) of the last snapshot
        self._materials: dict[str, tuple] = {}
        self._next_materials: dict[str, tuple] = {}
        self.reused = 0  # meshes taken from here in the last snapshot (tests, panel)

    def __len__(self) -> int:
        return len(self._kept)

    def clear(self) -> None:
        """Forget every mesh: the next snapshot reads them all."""
        self._kept.clear()
        self._materials.clear()

    def forget_updated(self, records, data_of, key_owner=None) -> None:
        """Drop the meshes ``records`` (``changes.UpdateRecord``s) may have changed.

        data_of : object name → its mesh datablock's name (None when gone); key_owner : shape
        keys' (``Key``) name → the name of the mesh they belong to (None when unknown: every
        object with modifiers or shape keys is read again)."""
        if not self._kept:
            return
        objects, datas, modified = set(), set(), False
        for r in records:
            if not r.geometry:
                continue
            if r.id_type == "OBJECT":
                objects.add(r.name)
                data = data_of(r.name)
                if data is not None:
                    datas.add(data)
            elif r.id_type == "MESH":
                datas.add(r.name)
            elif r.id_type == "KEY" and key_owner is not None and key_owner(r.name) is not None:
                datas.add(key_owner(r.name))
            elif r.id_type not in _NOT_MODIFIER_INPUTS:
                modified = True
        if objects or datas or modified:
            self._kept = {key: a for key, a in self._kept.items()
                          if a.object not in objects and a.data not in datas
                          and not (modified and a.modified)}

    def holds(self, key: str, change: tuple) -> bool:
        """Are the arrays of ``key`` kept, read at ``change``?"""
        arrays = self._kept.get(key)
        return arrays is not None and arrays.change == change

    def keep(self, key: str, arrays: MeshArrays) -> None:
        """Keep arrays read ahead of a snapshot (``scene.read_ahead``): the next snapshot takes
        them unless an update forgets them first."""
        self._kept[key] = arrays

    # ------------------------------------------------------------------ a snapshot

    def begin(self) -> None:
        """A snapshot starts: what it reads or reuses is what the next one may reuse."""
        self._next, self._next_materials = {}, {}
        self.reused = 0

    def take(self, key: str, change: tuple | None) -> MeshArrays | None:
        """The arrays of ``key`` when they were read at ``change``, else None."""
        arrays = self._kept.get(key)
        if arrays is None or change is None or arrays.change != change:
            return None
        self.reused += 1
        if self._next is not None:
            self._next[key] = arrays
        return arrays

    def triangle_materials(self, key: str, arrays: MeshArrays, lookup: np.ndarray,
                           compute) -> np.ndarray:
        """``compute()`` (the triangles' material indices from ``arrays.slots`` and the slots'
        ``lookup``), or the same array as the last snapshot's when both were the same."""
        last = self._materials.get(key)
        if last is not None and last[0] is arrays and np.array_equal(last[1], lookup):
            values = last[2]
        else:
            values = compute()
        if self._next is not None:
            self._next_materials[key] = (arrays, lookup, values)
        return values

    def put(self, key: str, arrays: MeshArrays) -> None:
        """Keep what this snapshot read of ``key``."""
        if self._next is not None:
            self._next[key] = arrays

    def end(self) -> None:
        """The snapshot is complete: keep only its meshes (an object gone is read when back)."""
        if self._next is not None:
            self._kept, self._next = self._next, None
            self._materials, self._next_materials = self._next_materials, {}

"""What each kind of ray sees of the voxels: Cycles' ray visibility in Fast quality
(docs/gi_pipeline.md "Ray visibility and holdouts", issue 18).

An object hidden from a kind of ray (``ObjectData.visibility``, the ``snapshot.RAY_*`` bits)
leaves its voxels out of what the cones of that kind march through:

* **diffuse** — the diffuse cones and AO (Accurate's AO comes from its diffuse rays too): the
  update's main cascades, light and octree (``GIState.cascades`` / ``octree``);
* **glossy** — the glossy cones;
* **shadow** — the occupancy that shadows the voxels' injected light, and the octree of the
  shadow cones (shadows "CONES": lamps, emitters and the world's visible share).

Camera visibility and holdouts are the primary hits' (the G-buffer and ``primary_visibility``),
not the voxels'.

Each kind is its own merge of the objects' placed voxels (``cascades.Placement``) rather than a
visibility bit per voxel: an octree node prefilters occlusion and colour over its children, so
a mask per voxel would still need an octree per kind to be read by a cone. When every object is
seen by every ray (the common scene) the kinds share one merge and one octree and nothing costs
more; otherwise a kind whose visible objects differ from the diffuse rays' gets its own merge,
injection (glossy) and octree: up to three.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..scene.snapshot import RAY_ALL, RAY_DIFFUSE, RAY_GLOSSY, RAY_SHADOW
from .cascades import merge_placement

__all__ = ["KINDS", "VoxelView", "visible_objects", "view_cascades", "view_octrees",
           "view_octree"]

KINDS = {"diffuse": RAY_DIFFUSE, "glossy": RAY_GLOSSY, "shadow": RAY_SHADOW}


@dataclass(eq=False)
class VoxelView:
    """The voxels one kind of ray sees where they differ from the diffuse rays': cascades
    (``CascadeVoxels`` per grid), their injected radiance (None for shadows: only occlusion is
    read) and octree."""

    cascades: list
    radiance: object
    octree: object


def visible_objects(snapshot, ray: int) -> frozenset | None:
    """Names of the objects that rays of kind ``ray`` (a ``RAY_*`` bit) see; None when they see
    every object."""
    bits = {o.name: int(getattr(o, "visibility", RAY_ALL)) for o in snapshot.objects}
    if all(b & ray for b in bits.values()):
        return None
    return frozenset(name for name, b in bits.items() if b & ray)


def view_cascades(placement, grids, snapshot) -> dict:
    """Per kind of ``KINDS`` the merged cascades its rays see; kinds that see the same objects
    share one list (the same object)."""
    merged: dict = {}
    out = {}
    for kind, ray in KINDS.items():
        names = visible_objects(snapshot, ray)
        if names is not None:
            names = frozenset(names & placement.objects.keys())
            if names == placement.objects.keys():
                names = None
        if names not in merged:
            part = placement if names is None else dataclasses.replace(
                placement, objects={k: v for k, v in placement.objects.items() if k in names})
            merged[names] = merge_placement(part, grids)
        out[kind] = merged[names]
    return out


def view_octrees(views: dict, snapshot, occupancy, inject, build) -> dict:
    """The ``VoxelView`` of each kind whose cascades are not the diffuse ones (``views`` from
    ``view_cascades``). inject(cascades, snapshot, occupancy) -> radiance and
    build(cascades, radiance) -> octree are the update's own stages (same samples and
    settings); shadow views get zero radiance (their cones read occlusion only)."""
    out = {}
    for kind in ("glossy", "shadow"):
        cascades = views[kind]
        if cascades is views["diffuse"]:
            continue
        if kind == "shadow":
            radiance = None
            zeros = [np.zeros((cv.voxel_count, 3), np.float32) for cv in cascades]
            octree = build(cascades, zeros)
        else:
            radiance = inject(cascades, snapshot, occupancy)
            octree = build(cascades, radiance)
        out[kind] = VoxelView(cascades, radiance, octree)
    return out


def view_octree(state, kind: str):
    """The octree the cones of ``kind`` ("diffuse", "glossy" or "shadow") march through in the
    update ``state`` (``update.GIState``)."""
    if kind not in KINDS:
        raise ValueError(f"kind of ray must be one of {tuple(KINDS)}, got {kind!r}")
    view = (getattr(state, "ray_views", None) or {}).get(kind)
    return state.octree if view is None else view.octree

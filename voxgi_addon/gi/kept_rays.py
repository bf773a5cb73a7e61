"""What one light injection leaves for the next (docs/gi_pipeline.md "Posed updates").

A voxel's shadow rays are drawn from its cell (``light_injection.voxel_ids``), so a voxel that
stays where it was casts the same rays as before, and a ray that meets no cell whose occupancy
changed ends as it did. ``ShadowRays`` keeps every ray of an injection with its result, keyed
by the ray's exact bits (origin, direction, length); ``KeptRays`` is the occluder the next
injection marches through: a ray it finds there that meets none of the changed cells
(``ShadowRays.changed``: boxes per cascade) is not marched again. ``KeptLight`` keeps each
voxel's direct light: a voxel in the same cell with the same normal, none of whose rays meets
a changed cell, under the same lights, is not lit again at all. Either way the result is the
one marching every ray gives.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .direct_light import _NORMAL_OFFSET
from .voxel_shadows import CascadeOccupancy

__all__ = ["ShadowRays", "KeptLight", "KeptRays", "ray_origins", "voxel_words"]

_RAY_WORDS = 7  # a ray: origin (3), direction (3), length, as float64 bit patterns


def _words(*columns) -> np.ndarray:
    """(N, k) uint64: the bits of k float64 columns ((N,) or (N, c) arrays)."""
    rows = np.column_stack([np.asarray(c, np.float64).reshape(len(c), -1) for c in columns])
    return np.ascontiguousarray(rows).view(np.uint64)


def _keys(words) -> np.ndarray:
    """(N,) uint64 hashes of ``words`` rows (matches are checked word by word)."""
    key = np.full(len(words), 0xCBF29CE484222325, np.uint64)
    with np.errstate(over="ignore"):
        for k in range(words.shape[1]):
            key = (key ^ words[:, k]) * np.uint64(0x100000001B3)
            key ^= key >> np.uint64(29)
    return key


def _find(keys, words, sorted_keys, sorted_words) -> tuple[np.ndarray, np.ndarray]:
    """(found (N,) bool, row (N,) into the sorted table) of ``words`` rows."""
    if len(sorted_keys) == 0 or len(words) == 0:
        return np.zeros(len(words), bool), np.zeros(len(words), np.int64)
    at = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
    found = sorted_keys[at] == keys
    rows = sorted_words[at]
    for k in range(words.shape[1]):  # a column at a time (``all`` over short rows is slow)
        found &= rows[:, k] == words[:, k]
    return found, at


def ray_origins(start, normals) -> np.ndarray:
    """(N, 3) where the shadow rays of surface points ``start`` (N, 3) with unit ``normals``
    leave: as ``direct_light`` lifts them, bit for bit."""
    return np.asarray(start, np.float64) + _NORMAL_OFFSET * np.asarray(normals, np.float64)


def voxel_words(ids, normals) -> np.ndarray:
    """(N, 4) uint64: a voxel's id and unit normal, what its shadow rays are drawn from."""
    return _words(np.asarray(ids, np.int64).view(np.float64), normals)


@dataclass(eq=False)
class KeptLight:
    """Each voxel's direct light under ``lights`` (a key of the lights, world and samples):
    ``keys`` (N,) sorted, ``words`` (N, 4) (``voxel_words``) and ``direct`` (N, 3) float64 in
    that order."""

    lights: tuple
    keys: np.ndarray
    words: np.ndarray
    direct: np.ndarray


@dataclass(eq=False)
class ShadowRays:
    """The shadow rays one injection cast through ``occupancy``: ``keys`` (R,) uint64 sorted,
    ``words`` (R, 7) and ``blocked`` (R,) bool in that order, and its voxels' light
    (``KeptLight``, or None)."""

    occupancy: CascadeOccupancy
    keys: np.ndarray
    words: np.ndarray
    blocked: np.ndarray
    light: KeptLight | None = None
    _origin_keys: np.ndarray | None = None

    @property
    def origin_keys(self) -> np.ndarray:
        """(R,) uint64 keys of the rays' origins (``_keys`` of their first 3 words)."""
        if self._origin_keys is None:
            self._origin_keys = _keys(np.ascontiguousarray(self.words[:, :3]))
        return self._origin_keys

    def lookup(self, words) -> tuple[np.ndarray, np.ndarray]:
        """(found (N,) bool, blocked (N,) bool) of rays given as (N, 7) words."""
        found, at = _find(_keys(words), words, self.keys, self.words)
        return found, found & self.blocked[at] if len(self.blocked) else found

    def changed(self, occupancy: CascadeOccupancy) -> np.ndarray | None:
        """(B, 2, 3) world boxes holding every cell whose occupancy, as a ray reads it there,
        differs between this injection's ``occupancy`` and ``occupancy``; None when they
        cannot be compared (other grids: every ray is marched again)."""
        old, new = self.occupancy, occupancy
        if not (old.nested and new.nested) or len(old.grids) != len(new.grids) or any(
                a[2] != b[2] or a[1] != b[1] or not np.array_equal(a[0], b[0])
                for a, b in zip(old.grids, new.grids)):
            return None
        boxes = []
        for index, (origin, span, res, _) in enumerate(new.grids):
            differ = old.combined[index] != new.combined[index]
            if index > 0:  # the finer cascade's region reads the finer cascade's cells
                q = res // 4
                differ[q:3 * q, q:3 * q, q:3 * q] = False
            flat = np.flatnonzero(differ)  # (argwhere's (K, 3) is 10 times slower)
            if len(flat):
                cells = np.stack(np.unravel_index(flat, differ.shape), axis=1)
                boxes.extend(_cell_boxes(cells, origin, span))
        return np.array(boxes, np.float64).reshape(-1, 2, 3)


# A cascade's changed cells are boxed in up to SPLIT³ boxes: their bounds cut in a SPLIT³
# grid, each part holding some tightened to them. One box around a character whose arms and
# legs swing took ~700 voxels that stayed where they were, lit past the limbs, for changed
# (docs/gi_pipeline.md "Posed updates").
SPLIT = 4


def _cell_boxes(cells, origin, span) -> list[tuple[np.ndarray, np.ndarray]]:
    """World boxes (low, high) around ``cells`` (K, 3) of a grid at ``origin``, ``span``: the
    cells' bounds cut into SPLIT³ parts, each part's cells' bounds (padded by 1e-6 span)."""
    low, high = cells.min(axis=0), cells.max(axis=0) + 1
    size = np.maximum(1, -(-(high - low) // SPLIT))  # cells per part, rounded up
    part = (cells - low) // size
    key = (part[:, 0] * SPLIT + part[:, 1]) * SPLIT + part[:, 2]
    order = np.argsort(key, kind="stable")
    key, cells = key[order], cells[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    lows = np.minimum.reduceat(cells, starts, axis=0)
    highs = np.maximum.reduceat(cells, starts, axis=0) + 1
    pad = 1e-6 * span
    return [(origin + a * span - pad, origin + b * span + pad) for a, b in zip(lows, highs)]


def meets_boxes(origins, dirs, max_t, boxes) -> np.ndarray:
    """(N,) bool: does each ray's segment [0, max_t] meet any of ``boxes`` (B, 2, 3)? Rays are
    tested against the boxes' common bounds first, and only those that meet them against each
    box (a ray that meets a box meets bounds around it: the slabs' arithmetic is monotone)."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 2, 3)
    max_t = np.broadcast_to(np.asarray(max_t, np.float64), (len(origins),))
    if len(boxes) <= 1:
        return _meets_each(origins, dirs, max_t, boxes)
    bounds = np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])[None]
    meets = _meets_each(origins, dirs, max_t, bounds)
    near = np.flatnonzero(meets)
    if len(near):
        meets[near] = _meets_each(origins[near], dirs[near], max_t[near], boxes)
    return meets


def _meets_each(origins, dirs, max_t, boxes) -> np.ndarray:
    """``meets_boxes`` one box after another."""
    meets = np.zeros(len(origins), bool)
    # parallel to a face: its slab by hand (columns at a time: reductions over rows of 3 are
    # 20–30 times slower)
    flat = np.flatnonzero((dirs[:, 0] == 0) | (dirs[:, 1] == 0) | (dirs[:, 2] == 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / dirs
        for low, high in boxes:
            t0 = (low - origins) * inverse
            t1 = (high - origins) * inverse
            near, far = np.minimum(t0, t1), np.maximum(t0, t1)
            if len(flat):
                o, d = origins[flat], dirs[flat]
                within = (o >= low) & (o <= high)
                near[flat] = np.where(d == 0, np.where(within, -np.inf, np.inf), near[flat])
                far[flat] = np.where(d == 0, np.where(within, np.inf, -np.inf), far[flat])
            enter = np.maximum(np.maximum(np.maximum(near[:, 0], near[:, 1]), near[:, 2]), 0.0)
            leave = np.minimum(np.minimum(np.minimum(far[:, 0], far[:, 1]), far[:, 2]), max_t)
            meets |= enter <= leave
    return meets


class KeptRays:
    """The occluder of an injection after ``previous`` (module doc): a ray found in
    ``previous`` that meets none of the changed cells takes its result from there, the others
    are marched through ``occupancy``; every ray is kept for the next injection (``kept``).

    ``lights`` keys the injection's lights: when they are ``previous``'s, ``light_of`` gives
    the voxels whose light can be taken as it was."""

    def __init__(self, occupancy: CascadeOccupancy, previous: ShadowRays | None,
                 lights: tuple | None = None):
        self.occupancy = occupancy
        self.previous = previous
        self.boxes = None if previous is None else previous.changed(occupancy)
        self.lights = lights
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []
        self.marched = self.reused = 0
        self.voxels: list[tuple[np.ndarray, np.ndarray]] = []  # (words, direct) per call
        self._dirty = None
        self._valid = None

    # ------------------------------------------------------------------ the occluder

    def local_span(self, points):
        return self.occupancy.local_span(points)

    def occluded(self, origins, dirs, max_t):
        origins = np.asarray(origins, np.float64)
        dirs = np.asarray(dirs, np.float64)
        max_t = np.broadcast_to(np.asarray(max_t, np.float64), (len(origins),))
        words = _words(origins, dirs, max_t)
        blocked = np.zeros(len(origins), bool)
        todo = np.ones(len(origins), bool)
        if self.boxes is not None:
            found, before = self.previous.lookup(words)
            if len(self.boxes) and found.any():
                at = np.flatnonzero(found)
                found[at] = ~meets_boxes(origins[at], dirs[at], max_t[at], self.boxes)
            blocked[found] = before[found]
            todo = ~found
        if todo.any():
            blocked[todo] = self.occupancy.occluded(origins[todo], dirs[todo], max_t[todo])
        self.marched += int(todo.sum())
        self.reused += int(len(todo) - todo.sum())
        self.parts.append((words, blocked))
        return blocked

    # ------------------------------------------------------------------ voxels' light

    def _previous_rays(self):
        """(valid (R,) bool: a previous ray that meets no changed cell; keys and words of the
        origins of those that do, sorted)."""
        if self._valid is None:
            rays = self.previous
            origins = rays.words[:, :3].view(np.float64)
            dirs = rays.words[:, 3:6].view(np.float64)
            max_t = rays.words[:, 6].view(np.float64)
            self._valid = ~meets_boxes(origins, dirs, max_t, self.boxes) if len(self.boxes) \
                else np.ones(len(rays.keys), bool)
            dirty = np.ascontiguousarray(rays.words[~self._valid, :3])
            keys = rays.origin_keys[~self._valid]
            order = np.argsort(keys)
            self._dirty = (keys[order], dirty[order])
        return self._valid, self._dirty

    def light_of(self, ids, normals, origins) -> tuple[np.ndarray, np.ndarray]:
        """(kept (N,) bool, direct (N, 3) float64): the voxels (``ids``, unit ``normals``, their
        rays' ``origins``) whose light is ``previous``'s — the same voxel, none of its rays
        meeting a changed cell, the same lights — and that light (0 elsewhere)."""
        kept = np.zeros(len(ids), bool)
        direct = np.zeros((len(ids), 3))
        light = None if self.previous is None else self.previous.light
        if self.boxes is None or light is None or light.lights != self.lights:
            return kept, direct
        words = voxel_words(ids, normals)
        found, at = _find(_keys(words), words, light.keys, light.words)
        _, (dirty_keys, dirty_words) = self._previous_rays()
        origin_words = _words(origins)
        dirty, _ = _find(_keys(origin_words), origin_words, dirty_keys, dirty_words)
        kept = found & ~dirty
        direct[kept] = light.direct[at[kept]]
        return kept, direct

    def keep_light(self, ids, normals, direct) -> None:
        """Note the voxels' direct light (N, 3) for the next injection."""
        self.voxels.append((voxel_words(ids, normals), np.asarray(direct, np.float64)))

    def kept(self, origins_kept=None) -> ShadowRays:
        """The rays and light of this injection, for the next one. origins_kept : (M, 3) the ray
        origins of voxels whose light was taken from ``previous`` (``light_of``): their rays
        were not cast again, so ``previous``'s that meet no changed cell are carried over."""
        words = [w for w, _ in self.parts] or [np.zeros((0, _RAY_WORDS), np.uint64)]
        blocked = [b for _, b in self.parts] or [np.zeros(0, bool)]
        keys = [_keys(np.concatenate(words))]
        if origins_kept is not None and len(origins_kept) and self.previous is not None:
            valid, _ = self._previous_rays()
            rays = self.previous
            origin_words = _words(origins_kept)
            order_keys = _keys(origin_words)
            order = np.argsort(order_keys)
            mine, _ = _find(rays.origin_keys, rays.words[:, :3], order_keys[order],
                            origin_words[order])
            carry = valid & mine
            words.append(rays.words[carry])
            blocked.append(rays.blocked[carry])
            keys.append(rays.keys[carry])
        words, blocked, keys = np.concatenate(words), np.concatenate(blocked), np.concatenate(keys)
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        first = order[np.concatenate([[True], keys[1:] != keys[:-1]])] if len(keys) else order
        keys = keys[np.concatenate([[True], keys[1:] != keys[:-1]])] if len(keys) else keys
        light = None
        if self.lights is not None and self.voxels:
            vwords = np.concatenate([w for w, _ in self.voxels])
            vkeys = _keys(vwords)
            order = np.argsort(vkeys)
            light = KeptLight(self.lights, vkeys[order], vwords[order],
                              np.concatenate([d for _, d in self.voxels])[order])
        return ShadowRays(self.occupancy, keys, words[first], blocked[first], light)

"""A bounding volume hierarchy over the scene's triangles, laid out for stackless GPU traversal.

``build_bvh`` builds a binary BVH with binned SAH splits (``BINS`` centroid bins on the axis of
largest centroid extent), level by level: every node of a level is split in the same few numpy
calls, so the build costs O(T log T) array work and no per-node Python (100k triangles in about
0.3 s). Leaves hold at most ``MAX_LEAF`` triangles; a node whose centroids all coincide is split
at its median.

The nodes are stored in depth-first order (left child first) as a *threaded* BVH: an interior
node's first child is the next node, and every node has a "miss" link to the node that follows
its subtree in depth-first order (-1 past the end). Traversal is then a loop without a stack::

    node = 0
    while node >= 0:
        if the ray meets node's box (within [t_min, best t]):
            if interior: node += 1; continue
            test the leaf's triangles
        node = miss[node]

``pack_bvh`` turns a BVH into RGBA32F texels for ``render/shaders/bvh_common.glsl`` (2D textures
``TEXTURE_WIDTH`` texels wide, texel k at (k mod width, k div width); integers are stored as
float values, exact below 2²⁴). It packs the nodes in ``ORDERS`` depth-first layouts, one per
major ray direction (``ordered_layouts``: the child nearer along that direction first, so a
closest-hit ray finds its hit early and skips the farther subtrees; Hachisuka's
multiple-threaded BVH), while they fit ``ORDERED_BYTES``, else in the BVH's own order; the
GPU picks a layout per ray (docs/gi_pipeline.md "A layout of the BVH per ray direction").
``traverse`` is the numpy statement of the GLSL traversal of one layout (vectorised over rays;
tests compare it with brute force and with ``raycast``; every layout finds the same hits).

Units: world space, metres, as ``SceneTriangles``.
"""
from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import numpy as np

from .geometry import SceneTriangles
from .raycast import SHADOW_EPSILON, counted_hits, cutouts_of
from .short_axis import max_along, min_along, norm3
from .snapshot import RAY_ALL, RAY_DIFFUSE, RAY_SHADOW

__all__ = [
    "BINS",
    "BVH",
    "DET_EPSILON",
    "MAX_LEAF",
    "NODE_TEXELS",
    "ORDERED_BYTES",
    "ORDERS",
    "SHADOW_LAYOUT",
    "TEXTURE_WIDTH",
    "TRIANGLE_TEXELS",
    "BVHTextures",
    "HIDDEN_SHIFT",
    "LEAF_BIAS",
    "build_bvh",
    "bvh_of",
    "closest_hits",
    "leaf_codes",
    "material_code",
    "node_layouts",
    "occluded",
    "ordered_layouts",
    "pack_bvh",
    "traverse",
]

BINS = 16               # SAH bins per split
MAX_LEAF = 8            # most triangles in a leaf (the leaf code keeps 4 bits for the count)
TRAVERSAL_COST = 1.0    # SAH cost of visiting a node, relative to one triangle test
TEXTURE_WIDTH = 4096    # texels per row of the packed textures (a power of two)
NODE_TEXELS = 2         # (lo.xyz, miss), (hi.xyz, leaf code)
ORDERS = 6              # packed node layouts, one per major ray direction (``ordered_layouts``)
SHADOW_LAYOUT = 5       # the layout every shadow ray walks: −z, the upper child first
# the most bytes of node texels packed in ORDERS layouts (``node_layouts``): the viewport uploads
# the node texture in one call on the main thread, about 2.4 GB/s here (48 MB: ~20 ms)
ORDERED_BYTES = 48 << 20
TRIANGLE_TEXELS = 3     # (v0.xyz, material code), (e1.xyz, triangle index), (e2.xyz, |e1|·|e2|)
HIDDEN_SHIFT = 1 << 16  # material code = material + HIDDEN_SHIFT · (RAY_* bits it is hidden from)
DET_EPSILON = 1e-12     # as raycast's Möller–Trumbore: |det| > ε·|e1|·|e2|·|d| or no hit
_LEAF_SHIFT = 16        # leaf code = first · 16 + count
LEAF_BIAS = 1 << 23     # packed leaf codes: the float whose bits are code + LEAF_BIAS (normal)
_MAX_TRIANGLES = 1 << 23  # node links and triangle indices are floats, exact below 2^24
_BOX_PAD = 1e-5         # node boxes grow by this fraction of the scene's size (float32 safety)


@dataclass(frozen=True, eq=False)
class BVH:
    """A threaded BVH (see the module doc), nodes in depth-first order.

    lo, hi : (N, 3) float64 node bounds in metres, padded by ``_BOX_PAD`` × the scene's size.
    miss : (N,) int32 the node after this one's subtree in depth-first order, -1 = none.
    first, count : (N,) int32 a leaf's triangles are ``order[first:first + count]``; interior
        nodes have count 0 (and first -1). An interior node's children are node + 1 and
        ``miss[node + 1]``.
    order : (T,) int32 indices into the ``SceneTriangles``, grouped by leaf.
    depth : levels of the tree (1 for a single leaf).
    """

    lo: np.ndarray
    hi: np.ndarray
    miss: np.ndarray
    first: np.ndarray
    count: np.ndarray
    order: np.ndarray
    depth: int

    def __len__(self) -> int:
        return len(self.miss)


def _area(lo, hi):
    e = np.maximum(hi - lo, 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def _ranges(start, count):
    """Concatenated aranges [start_i, start_i + count_i) and the offset of each in the result."""
    offsets = np.cumsum(count) - count
    return np.repeat(start - offsets, count) + np.arange(int(count.sum())), offsets


def _running(values, op):
    """``op.accumulate(values, axis=1)`` of (A, bins, 3) values, a bin at a time (a few
    ops over (A, 3) rows: the ufunc's accumulate along a middle axis loops per row)."""
    out = np.empty_like(values)
    out[:, 0] = values[:, 0]
    for k in range(1, values.shape[1]):
        op(out[:, k - 1], values[:, k], out=out[:, k])
    return out


def _split_level(order, lo3, hi3, cen3, start, count, bins=BINS, max_leaf=MAX_LEAF):
    """Choose splits for a level's nodes with ``bins`` SAH bins. Returns (split (A,) bool,
    left count (A,)) and reorders ``order`` in place so that each split node's left part
    comes first. lo3, hi3, cen3 : (3, T) the triangles' boxes and centroids, a row per axis
    (contiguous: every gather below is of one 1D row)."""
    a = len(start)
    pos, offsets = _ranges(start, count)
    tri = order[pos]
    seg = np.repeat(np.arange(a), count)
    c = [row[tri] for row in cen3]
    cmin = np.stack([np.minimum.reduceat(x, offsets) for x in c], axis=1)
    cmax = np.stack([np.maximum.reduceat(x, offsets) for x in c], axis=1)
    ext = cmax - cmin
    axis = np.argmax(ext, axis=1)
    rows = np.arange(a)
    e = ext[rows, axis]
    scale = np.divide(bins, e, out=np.zeros_like(e), where=e > 0)
    # per triangle: its centroid along its node's axis, from the node's low end, in bins
    axis_t, lo_c, scale_t = axis[seg], cmin[rows, axis][seg], scale[seg]
    value = np.where(axis_t == 0, c[0], np.where(axis_t == 1, c[1], c[2])) - lo_c
    b = np.clip((value * scale_t).astype(np.int64), 0, bins - 1)
    key = seg * bins + b
    counts = np.bincount(key, minlength=a * bins).reshape(a, bins)
    blo = np.full((3, a * bins), np.inf, lo3.dtype)
    bhi = np.full((3, a * bins), -np.inf, hi3.dtype)
    for k in range(3):  # ufunc.at is fast on contiguous 1D arrays of the values' dtype
        np.minimum.at(blo[k], key, lo3[k][tri])
        np.maximum.at(bhi[k], key, hi3[k][tri])
    blo, bhi = blo.T.reshape(a, bins, 3), bhi.T.reshape(a, bins, 3)
    left_n = np.cumsum(counts, axis=1)[:, :-1]
    right_n = count[:, None] - left_n
    left_area = _area(_running(blo, np.minimum), _running(bhi, np.maximum))[:, :-1]
    right_area = _area(_running(blo[:, ::-1], np.minimum),
                       _running(bhi[:, ::-1], np.maximum))[:, ::-1][:, 1:]
    with np.errstate(invalid="ignore"):
        cost = np.where((left_n > 0) & (right_n > 0),
                        left_area * left_n + right_area * right_n, np.inf)
    best = np.argmin(cost, axis=1)
    best_cost = cost[rows, best]
    parent = np.maximum(_area(_bounds_min(blo), _bounds_max(bhi)), 1e-30)
    sah = np.isfinite(best_cost)
    leaf = (count <= 1) | ((count <= max_leaf) &
                           (~sah | (count <= TRAVERSAL_COST + best_cost / parent)))
    split = ~leaf
    median = split & ~sah  # every centroid in one place: split the list in half
    left = np.where(sah, left_n[rows, np.minimum(best, bins - 2)], count // 2)
    # Reorder the split nodes' triangles: left side first, stable within each side.
    moving = split[seg]
    if not moving.any():
        return split, left
    mseg = seg[moving]
    side = np.where(median[mseg], (np.flatnonzero(moving) - offsets[mseg]) >= count[mseg] // 2,
                    b[moving] > best[mseg])
    key2 = mseg * 2 + side
    order[pos[moving]] = tri[moving][np.argsort(key2, kind="stable")]
    return split, left


def _bounds_min(blo):
    """(A, 3) the low corner over the bins of (A, bins, 3)."""
    out = blo[:, 0].copy()
    for k in range(1, blo.shape[1]):
        np.minimum(out, blo[:, k], out=out)
    return out


def _bounds_max(bhi):
    out = bhi[:, 0].copy()
    for k in range(1, bhi.shape[1]):
        np.maximum(out, bhi[:, k], out=out)
    return out


def _finite_boxes(tlo: np.ndarray, thi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles' boxes (T, 3) with those of a triangle with a NaN or infinite corner made
    a point amid the others' (their boxes' middle): no ray hits such a triangle (the triangle
    tests fail on it), and its box must not turn its nodes' bounds NaN, which would hide
    every triangle beside it."""
    broken = ~(np.isfinite(tlo).all(axis=1) & np.isfinite(thi).all(axis=1))
    if not broken.any():
        return tlo, thi
    good = ~broken
    middle = 0.5 * (tlo[good].min(axis=0) + thi[good].max(axis=0)) if good.any() else 0.0
    tlo, thi = tlo.copy(), thi.copy()
    tlo[broken] = middle
    thi[broken] = middle
    return tlo, thi


def build_bvh(tris: SceneTriangles, max_leaf: int = MAX_LEAF) -> BVH:
    """A threaded binned-SAH ``BVH`` over ``tris`` (see the module doc); leaves hold at most
    ``max_leaf`` triangles."""
    positions = np.asarray(tris.positions, dtype=np.float64).reshape(-1, 3, 3)
    t = len(positions)
    if t > _MAX_TRIANGLES:
        raise ValueError(f"{t} triangles: the packed BVH holds at most {_MAX_TRIANGLES}")
    tlo, thi = _finite_boxes(min_along(positions, 1), max_along(positions, 1))
    # The split search works in float32 (half the memory traffic); bounds are float64.
    blo32 = np.ascontiguousarray(tlo.T, np.float32)  # (3, T): a row per axis
    bhi32 = np.ascontiguousarray(thi.T, np.float32)
    cen = 0.5 * (blo32 + bhi32)
    order = np.arange(t, dtype=np.int64)
    # Nodes in creation (breadth-first) order.
    starts, counts, lefts, levels = [np.zeros(1, np.int64)], [np.array([t], np.int64)], [], []
    level_start = np.zeros(1, np.int64)
    level_count = np.array([t], np.int64)
    level_ids = np.zeros(1, np.int64)
    next_id = 1
    while len(level_ids):
        levels.append(level_ids)
        if t == 0:
            lefts.append(np.full(1, -1, np.int64))
            break
        split = np.zeros(len(level_ids), bool)
        left = np.zeros(len(level_ids), np.int64)
        # Small nodes get fewer bins: the per-bin arrays, not the triangles, dominate deep levels.
        groups = ((level_count > 4 * BINS, BINS),
                  ((level_count > MAX_LEAF) & (level_count <= 4 * BINS), BINS // 2),
                  ((level_count > 1) & (level_count <= MAX_LEAF), BINS // 4))
        for group, bins in groups:
            if group.any():
                split[group], left[group] = _split_level(order, blo32, bhi32, cen, level_start[group],
                                                         level_count[group], bins, max_leaf)
        parents = np.flatnonzero(split)
        child = np.full(len(level_ids), -1, np.int64)
        child[parents] = next_id + 2 * np.arange(len(parents))
        lefts.append(child)
        s, c, n = level_start[parents], level_count[parents], left[parents]
        level_start = np.stack([s, s + n], axis=1).ravel()
        level_count = np.stack([n, c - n], axis=1).ravel()
        level_ids = next_id + np.arange(2 * len(parents), dtype=np.int64)
        next_id += len(level_ids)
        starts.append(level_start)
        counts.append(level_count)
    start = np.concatenate(starts)
    count = np.concatenate(counts)
    left_child = np.concatenate(lefts)
    total = len(start)
    interior = left_child >= 0
    # Subtree sizes bottom-up, then depth-first (pre-order) positions top-down.
    size = np.ones(total, np.int64)
    for ids in reversed(levels):
        inner = ids[interior[ids]]
        size[inner] = 1 + size[left_child[inner]] + size[left_child[inner] + 1]
    pre = np.zeros(total, np.int64)
    for ids in levels:
        inner = ids[interior[ids]]
        pre[left_child[inner]] = pre[inner] + 1
        pre[left_child[inner] + 1] = pre[inner] + 1 + size[left_child[inner]]
    miss = pre + size
    miss[miss >= total] = -1
    # Bounds: leaves from their triangle ranges, interior nodes from their children (bottom-up).
    lo = np.zeros((total, 3))
    hi = np.zeros((total, 3))
    if t:
        leaves = np.flatnonzero(~interior)
        pos, offsets = _ranges(start[leaves], count[leaves])
        lo[leaves] = np.minimum.reduceat(tlo[order[pos]], offsets, axis=0)
        hi[leaves] = np.maximum.reduceat(thi[order[pos]], offsets, axis=0)
        for ids in reversed(levels):
            inner = ids[interior[ids]]
            lo[inner] = np.minimum(lo[left_child[inner]], lo[left_child[inner] + 1])
            hi[inner] = np.maximum(hi[left_child[inner]], hi[left_child[inner] + 1])
        scene_lo, scene_hi = lo[0], hi[0]
        pad = _BOX_PAD * (float(np.max(scene_hi - scene_lo))
                          + float(np.abs(np.r_[scene_lo, scene_hi]).max())) + 1e-12
        lo, hi = lo - pad, hi + pad
    out = np.empty(total, np.int64)
    out[pre] = np.arange(total)  # depth-first position → creation id
    leaf = ~interior[out]
    return BVH(lo=lo[out], hi=hi[out], miss=miss[out].astype(np.int32),
               first=np.where(leaf, start[out], -1).astype(np.int32),
               count=np.where(leaf, count[out], 0).astype(np.int32),
               order=order.astype(np.int32), depth=len(levels))


# --------------------------------------------------------------------------- instanced meshes

def _soup(positions) -> SceneTriangles:
    """Bare SceneTriangles over (n, 3, 3) corners (what ``build_bvh`` reads)."""
    n = len(positions)
    return SceneTriangles(positions, np.zeros((n, 3)), np.zeros(n, np.int32), np.zeros(n, np.int32))


def instance_groups(tris: SceneTriangles):
    """(groups, rest) of a scene's triangles by ``SceneTriangles.object_meshes``: groups is a
    list of ((K,) int64 first-triangle indices, triangles per object) of the K ≥ 2 objects
    placing one mesh (each object's triangles are contiguous, in the mesh's order); rest (R,)
    int64 the other triangles. None when no mesh is placed twice."""
    meshes = getattr(tris, "object_meshes", None)
    if meshes is None or len(tris) == 0:
        return None
    objects = np.asarray(tris.objects)
    cut = np.flatnonzero(np.diff(objects)) + 1
    starts, ends = np.r_[0, cut], np.r_[cut, len(objects)]
    ids = objects[starts]
    if len(np.unique(ids)) != len(ids):  # an object's triangles are not in one run
        return None
    mesh, size = np.asarray(meshes)[ids], ends - starts
    key = mesh * (int(size.max()) + 1) + size  # same mesh and triangle count
    values, inverse, users = np.unique(key, return_inverse=True, return_counts=True)
    shared = (users[inverse] >= 2) & (mesh >= 0)
    if not shared.any():
        return None
    groups = [(starts[shared & (inverse == k)], int(size[shared & (inverse == k)][0]))
              for k in np.unique(inverse[shared])]
    rest = np.flatnonzero(np.repeat(~shared, size))
    return groups, rest


def _node_levels(bvh: BVH) -> list[np.ndarray]:
    """The nodes of ``bvh`` by depth (root first); an interior node's children are node + 1
    and miss[node + 1]."""
    levels = [np.zeros(1, np.int64)]
    while True:
        inner = levels[-1][bvh.first[levels[-1]] < 0]
        if len(inner) == 0 or len(bvh.order) == 0:
            return levels
        levels.append(np.concatenate([inner + 1, bvh.miss[inner + 1].astype(np.int64)]))


def _subtree_sizes(bvh: BVH) -> np.ndarray:
    """(N,) nodes in each node's subtree (the node itself included): its depth-first block
    ends where its miss link points (or at the end)."""
    end = np.where(bvh.miss >= 0, bvh.miss, len(bvh)).astype(np.int64)
    return end - np.arange(len(bvh))


def _subtrees(bvh: BVH, depth: int) -> np.ndarray:
    """The nodes at ``depth`` and the leaves above it: subtrees that together hold every
    node below the cut once, in depth-first order."""
    levels = _node_levels(bvh)
    cut = [ids[bvh.first[ids] >= 0] for ids in levels[:depth]]
    if depth < len(levels):
        cut.append(levels[depth])
    return np.sort(np.concatenate(cut))


def _placed_bounds(proto: BVH, tlo, thi, starts):
    """(K, N, 3) lo, hi of the nodes of ``proto`` (a BVH of one mesh's triangles) over each
    placement's own world-space triangles (first triangle ``starts[k]``): tight boxes whatever
    the placement's transform."""
    leaves = np.flatnonzero(proto.count > 0)
    leaves = leaves[np.argsort(proto.first[leaves])]
    slots = starts[:, None] + proto.order[None, :].astype(np.int64)
    lo = np.zeros((len(starts), len(proto), 3), tlo.dtype)
    hi = np.zeros_like(lo)
    offsets = proto.first[leaves]
    lo[:, leaves] = np.minimum.reduceat(tlo[slots], offsets, axis=1)
    hi[:, leaves] = np.maximum.reduceat(thi[slots], offsets, axis=1)
    for ids in reversed(_node_levels(proto)):
        inner = ids[proto.first[ids] < 0]
        right = proto.miss[inner + 1]
        lo[:, inner] = np.minimum(lo[:, inner + 1], lo[:, right])
        hi[:, inner] = np.maximum(hi[:, inner + 1], hi[:, right])
    return lo, hi


def build_instanced_bvh(tris: SceneTriangles, groups, rest) -> BVH:
    """One threaded BVH over all of ``tris``, built once per instanced mesh: a binned-SAH BVH
    of one placement of each mesh of ``groups`` (``instance_groups``) gives every placement
    its topology, with boxes from that placement's own triangles (O(T) array work instead of
    a SAH build over all T); the other triangles get one SAH BVH; a SAH tree over the
    placements' and that BVH's boxes (one per leaf) is on top, each of its leaves replaced by
    the subtree it holds (so the top's leaf links thread into the subtrees). The result is a
    flattened world-space BVH like ``build_bvh``'s (same traversal, same textures)."""
    positions = np.asarray(tris.positions, dtype=np.float64).reshape(-1, 3, 3)
    if len(positions) > _MAX_TRIANGLES:
        raise ValueError(f"{len(positions)} triangles: the packed BVH holds at most {_MAX_TRIANGLES}")
    # float32 boxes (half the memory traffic; the pad below covers their rounding)
    tlo, thi = _finite_boxes(min_along(positions, 1).astype(np.float32),
                             max_along(positions, 1).astype(np.float32))
    # items: the rest's BVH (if any), then every placement; per item its nodes and triangles
    lo, hi, miss, first, count, order, nodes, tris_of = [], [], [], [], [], [], [], []
    depth = 1
    if len(rest):
        own = build_bvh(_soup(positions[rest]))
        # its subtrees at the depth where there are about as many as placements become items
        # of their own, so the top tree mixes them with the placements where they are
        # (one item with the whole rest's box costs every ray a visit to both)
        cut = _subtrees(own, int(np.ceil(np.log2(max(2, sum(len(g) for g, _ in groups))))))
        block, _ = _ranges(cut, own_size := _subtree_sizes(own)[cut])
        inside = np.repeat(cut, own_size)
        local = own.miss[block].astype(np.int64)
        before = np.concatenate([[0], np.cumsum(own.count)])  # triangles before each node
        first0 = before[cut]  # the leaves of a subtree hold one run of ``order``
        lo.append(own.lo[block]), hi.append(own.hi[block])
        miss.append(np.where((local > inside) & (local < inside + np.repeat(own_size, own_size)),
                             local - inside, -1))
        first.append(np.where(own.count[block] > 0, own.first[block] - np.repeat(first0, own_size), -1))
        count.append(own.count[block])
        runs = before[cut + own_size] - first0
        order.append(rest[own.order[_ranges(first0, runs)[0]]])
        nodes.append(own_size), tris_of.append(runs)
        depth = own.depth
    for starts, size in groups:
        proto = build_bvh(_soup(positions[starts[0]:starts[0] + size]))
        depth = max(depth, proto.depth)
        glo, ghi = _placed_bounds(proto, tlo, thi, starts)
        k = len(starts)
        lo.append(glo.reshape(-1, 3).astype(np.float64)), hi.append(ghi.reshape(-1, 3).astype(np.float64))
        miss.append(np.tile(proto.miss, k)), first.append(np.tile(proto.first, k))
        count.append(np.tile(proto.count, k))
        order.append((starts[:, None] + proto.order[None, :]).ravel())
        nodes.append([len(proto)] * k), tris_of.append([size] * k)
    lo, hi = np.concatenate(lo), np.concatenate(hi)
    miss, first, count = np.concatenate(miss), np.concatenate(first), np.concatenate(count)
    order = np.concatenate(order)
    nodes, tris_of = np.concatenate(nodes).astype(np.int64), np.concatenate(tris_of).astype(np.int64)
    node_start, tri_start = np.cumsum(nodes) - nodes, np.cumsum(tris_of) - tris_of
    roots = node_start
    scene_lo, scene_hi = lo[roots].min(axis=0), hi[roots].max(axis=0)
    pad = _BOX_PAD * (float(np.max(scene_hi - scene_lo))
                      + float(np.abs(np.r_[scene_lo, scene_hi]).max())) + 1e-12
    lo, hi = lo - pad, hi + pad
    # the top: a SAH tree over the items' boxes (a triangle (lo, hi, lo) has that box)
    boxes = np.stack([lo[roots], hi[roots], lo[roots]], axis=1)
    top = build_bvh(_soup(boxes), max_leaf=1)
    is_leaf = top.count > 0
    item = np.where(is_leaf, top.order[np.maximum(top.first, 0)], -1).astype(np.int64)
    size = np.where(is_leaf, nodes[item], 1)
    at = np.cumsum(size) - size  # where each top node's block starts
    top_miss = np.where(top.miss >= 0, at[np.maximum(top.miss, 0)], -1)
    total = int(size.sum())
    out_lo, out_hi = np.empty((total, 3)), np.empty((total, 3))
    out_miss = np.empty(total, np.int64)
    out_first, out_count = np.full(total, -1, np.int64), np.zeros(total, np.int64)
    inner = np.flatnonzero(~is_leaf)
    out_lo[at[inner]], out_hi[at[inner]] = top.lo[inner], top.hi[inner]
    out_miss[at[inner]] = top_miss[inner]
    leaves = np.flatnonzero(is_leaf)
    items = item[leaves]
    src, _ = _ranges(node_start[items], nodes[items])
    dst, _ = _ranges(at[leaves], nodes[items])
    owner = np.repeat(np.arange(len(leaves)), nodes[items])
    out_lo[dst], out_hi[dst] = lo[src], hi[src]
    local = miss[src].astype(np.int64)
    out_miss[dst] = np.where(local >= 0, at[leaves][owner] + local, top_miss[leaves][owner])
    base = np.cumsum(tris_of[items]) - tris_of[items]  # the items' triangles, in this order
    out_first[dst] = np.where(count[src] > 0, base[owner] + first[src], -1)
    out_count[dst] = count[src]
    tri_src, _ = _ranges(tri_start[items], tris_of[items])
    return BVH(lo=out_lo, hi=out_hi, miss=out_miss.astype(np.int32),
               first=out_first.astype(np.int32), count=out_count.astype(np.int32),
               order=order[tri_src].astype(np.int32), depth=top.depth + depth)


def build_scene_bvh(tris: SceneTriangles) -> BVH:
    """The BVH of a scene's triangles: ``build_instanced_bvh`` where a mesh is placed by two
    objects or more (``instance_groups``), else ``build_bvh``."""
    found = instance_groups(tris)
    return build_bvh(tris) if found is None else build_instanced_bvh(tris, *found)


_BVHS: weakref.WeakKeyDictionary[SceneTriangles, BVH] = weakref.WeakKeyDictionary()


_BUILDING = threading.Lock()  # one build at a time: a second caller waits and takes it


def bvh_of(tris: SceneTriangles) -> BVH:
    """``build_scene_bvh(tris)``, cached per ``SceneTriangles`` object: the GPU scene packs it
    and the radiance cache's layout traces it (``radiance_cache._backs_in_solids``), from
    whichever thread comes first."""
    with _BUILDING:
        bvh = _BVHS.get(tris)
        if bvh is None:
            bvh = _BVHS[tris] = build_scene_bvh(tris)
    return bvh


# --------------------------------------------------------------------------- textures

@dataclass(frozen=True, eq=False)
class BVHTextures:
    """RGBA32F texel arrays for ``bvh_common.glsl``, each (rows, TEXTURE_WIDTH, 4) float32.

    nodes : 1 or ``ORDERS`` layouts (``node_layouts``) of equal rows, layout k the k-th of
        ``ordered_layouts`` (one: the BVH's own order), each
        2 texels per node: (lo.xyz, miss link), (hi.xyz, leaf code) with leaf code =
        first · 16 + count (first indexes the packed triangles) stored as the float whose bits
        are code + ``LEAF_BIAS`` (exact whatever the triangle count; ``leaf_codes`` reads it),
        or -1.0 for an interior node. ``ORDERS`` layouts take a multiple of ``ORDERS`` rows,
        one layout (its rows padded) one more than a multiple: the GPU tells them apart by
        the texture's height.
    triangles : 3 texels per triangle, in leaf order: (v0.xyz, material code), (e1.xyz,
        index into the SceneTriangles), (e2.xyz, ±|e1|·|e2|, negative for a cut-out:
        ``textures.cutout_hits``) — v0 and the edges in metres.
    normals : 3 texels per triangle, in leaf order: the shading normals at v0, v1, v2 (the
        face normal where the triangles carry no corner normals), w = 0.
        The material code (``material_code``) is the material index (-1 = none) plus
        ``HIDDEN_SHIFT`` × the ``RAY_*`` bits of the rays that do not see the triangle (its
        Cycles ray visibility): a triangle every ray sees holds its material index.
    node_count, triangle_count : how many are packed (rows are zero-padded).
    """

    nodes: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    node_count: int
    triangle_count: int

    @property
    def nbytes(self) -> int:
        return self.nodes.nbytes + self.triangles.nbytes + self.normals.nbytes


_PACK_CHUNK = 1 << 18


def _blank_rows(count: int) -> np.ndarray:
    """(rows, TEXTURE_WIDTH, 4) float32 zeros holding ``count`` texels (at least one row)."""
    return np.zeros((max(1, -(-count // TEXTURE_WIDTH)), TEXTURE_WIDTH, 4), np.float32)


def leaf_codes(values: np.ndarray) -> np.ndarray:
    """The leaf codes (first · 16 + count; -1 for an interior node) of packed node texels'
    w (``BVHTextures.nodes``), as ``bvh_common.glsl`` reads them."""
    values = np.asarray(values, np.float32)
    return np.where(values < 0, -1, values.view(np.int32).astype(np.int64) - LEAF_BIAS)


def material_code(tris: SceneTriangles) -> np.ndarray:
    """(T,) int64 the packed material code of each triangle (see ``BVHTextures``; decoded by
    ``bvh_common.glsl``'s ``bvh_triangle_material`` and ``bvh_hidden``)."""
    materials = np.asarray(tris.materials, np.int64)
    if getattr(tris, "visibility", None) is None:
        return materials
    hidden = ~np.asarray(tris.visibility, np.int64) & RAY_ALL
    return materials + HIDDEN_SHIFT * hidden


def ordered_layouts(bvh: BVH) -> tuple[np.ndarray, np.ndarray]:
    """The ``ORDERS`` depth-first layouts of ``bvh``'s nodes, one per major ray direction
    (+x, −x, +y, −y, +z, −z): in layout 2a + s every interior node's child whose box centre lies
    first along axis a (toward +a for s = 0, −a for s = 1) comes first, so a ray walking that
    way meets the nearer child first and its closest hit cuts the farther one's subtree short
    (Hachisuka's multiple-threaded BVH). Returns (position (ORDERS, N) int64: where each node of
    ``bvh`` stands in each layout; miss (ORDERS, N) int64: its miss link there, -1 = none)."""
    n = len(bvh)
    size = _subtree_sizes(bvh)
    centre = bvh.lo + bvh.hi
    position = np.zeros(ORDERS * n, np.int64)  # layout k's at k · n + node
    shift = n * np.arange(ORDERS)[:, None]
    for ids in _node_levels(bvh):
        inner = ids[bvh.first[ids] < 0]
        if len(inner) == 0:
            continue
        a, b = inner + 1, bvh.miss[inner + 1].astype(np.int64)
        lower = (centre[a] <= centre[b]).T  # (3, K): a comes first toward +axis
        higher = (centre[a] >= centre[b]).T
        ahead = np.stack([lower, higher], axis=1).reshape(ORDERS, -1)  # +x, −x, +y, −y, +z, −z
        near = np.where(ahead, a, b) + shift
        far = np.where(ahead, b, a) + shift
        start = position[inner + shift] + 1
        position[near] = start
        position[far] = start + size[near - shift]
    position = position.reshape(ORDERS, n)
    miss = position + size[None, :]
    miss[miss >= n] = -1
    return position, miss


def _layout_rows(node_count: int) -> int:
    """Texture rows of one layout of ``node_count`` nodes (at least one)."""
    return max(1, -(-NODE_TEXELS * node_count // TEXTURE_WIDTH))


def node_layouts(node_count: int) -> int:
    """How many node layouts ``pack_bvh`` packs for a BVH of ``node_count`` nodes: ``ORDERS``
    while their texture stays within ``ORDERED_BYTES``, else the one depth-first layout."""
    return ORDERS if ORDERS * _layout_rows(node_count) * TEXTURE_WIDTH * 16 <= ORDERED_BYTES \
        else 1


def pack_bvh(bvh: BVH, tris: SceneTriangles, layouts: int | None = None) -> BVHTextures:
    """The texel arrays of ``bvh`` over ``tris`` (see ``BVHTextures``). layouts : ``ORDERS``
    (``ordered_layouts``) or 1 (the BVH's own depth-first order); None: ``node_layouts``."""
    n = len(bvh)
    layouts = node_layouts(n) if layouts is None else int(layouts)
    code = (bvh.first.astype(np.int64) * _LEAF_SHIFT + bvh.count + LEAF_BIAS).astype(np.int32)
    leaf = np.where(bvh.first >= 0, code.view(np.float32), np.float32(-1.0))
    rows = _layout_rows(n)
    if layouts == 1:  # rows ≡ 1 (mod ORDERS): what tells the GPU there is one layout
        rows += (1 - rows) % ORDERS
    nodes = np.zeros((layouts, rows * TEXTURE_WIDTH // NODE_TEXELS, NODE_TEXELS, 4), np.float32)
    placed = ordered_layouts(bvh) if layouts == ORDERS else \
        (np.arange(n)[None], bvh.miss.astype(np.int64)[None])
    block = np.empty((n, NODE_TEXELS, 4), np.float32)  # the texels in the BVH's node order
    block[:, 0, :3], block[:, 1, :3], block[:, 1, 3] = bvh.lo, bvh.hi, leaf
    for layout, (pos, miss) in enumerate(zip(*placed)):
        block[:, 0, 3] = miss
        nodes[layout, pos] = block
    order = bvh.order
    t = len(order)
    positions = np.asarray(tris.positions, dtype=np.float64).reshape(-1, 3, 3)
    codes = material_code(tris)
    cutout = cutouts_of(tris)
    corner_normals = tris.corner_normals
    # written in place into the textures' rows, _PACK_CHUNK triangles at a time (the float64
    # temporaries of all triangles at once took ~400 MB at a million triangles)
    triangles, normals = _blank_rows(3 * t), _blank_rows(3 * t)
    packed = triangles.reshape(-1, 4)[:3 * t].reshape(t, 3, 4)
    shading = normals.reshape(-1, 4)[:3 * t].reshape(t, 3, 4)
    for a in range(0, t, _PACK_CHUNK):
        b = min(t, a + _PACK_CHUNK)
        which = order[a:b]
        p = positions[which]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        packed[a:b, 0, :3], packed[a:b, 0, 3] = p[:, 0], codes[which]
        packed[a:b, 1, :3], packed[a:b, 1, 3] = e1, which
        packed[a:b, 2, :3] = e2
        packed[a:b, 2, 3] = norm3(e1) * norm3(e2)
        if cutout is not None:  # cut-outs (textures.cutout_hits) carry a negative scale
            packed[a:b, 2, 3] *= np.where(cutout[0].cutout[which], -1.0, 1.0)
        if corner_normals is not None:
            shading[a:b, :, :3] = np.asarray(corner_normals)[which]
        else:
            shading[a:b, :, :3] = np.asarray(tris.normals)[which][:, None]
    return BVHTextures(nodes.reshape(layouts * rows, TEXTURE_WIDTH, 4), triangles, normals, n, t)


# --------------------------------------------------------------------------- numpy traversal

def _intersect(p, o, d):
    """Double-sided Möller–Trumbore of rays o, d (P, 3) with triangles p (P, 3, 3) → t, u, v
    (t = inf on a miss), with raycast's determinant test."""
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    pv = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pv)
    scale = norm3(e1) * norm3(e2) * norm3(d)
    ok = np.abs(det) > DET_EPSILON * scale
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = o - p[:, 0]
    u = np.einsum("ij,ij->i", s, pv) * inv
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", d, q) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
    return np.where(hit, t, np.inf), u, v


def traverse(bvh: BVH, tris: SceneTriangles, origins, directions, t_min=0.0, t_max=np.inf,
             any_hit: bool = False, ray: int = RAY_ALL):
    """The stackless traversal of ``bvh_common.glsl`` in numpy (float64), vectorised over rays.

    origins, directions : (N, 3); t_min, t_max : scalar or (N,); hits with t_min < t < t_max
    count. Returns t (N,) (inf = miss), tri (N,) int64 (-1), u, v (N,) as
    ``raycast.closest_hits``; with ``any_hit`` a ray stops at its first hit (not the nearest).
    ray : the kind of ray (``snapshot.RAY_*``): triangles it does not see are passed through
    (``SceneTriangles.visibility``, packed as ``material_code``'s hidden bits).
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    lo_t = np.broadcast_to(np.asarray(t_min, np.float64), (n,))
    best = np.broadcast_to(np.asarray(t_max, np.float64), (n,)).copy()
    tri = np.full(n, -1, np.int64)
    bu, bv = np.zeros(n), np.zeros(n)
    if len(bvh.order) == 0:
        return np.full(n, np.inf), tri, bu, bv
    accept = tris.accepted(ray) if hasattr(tris, "accepted") else None
    positions = np.asarray(tris.positions, dtype=np.float64).reshape(-1, 3, 3)
    cutout = cutouts_of(tris)
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(np.abs(d) > 1e-30, d, 1e-30)
    node = np.zeros(n, np.int64)
    live = np.arange(n)
    while len(live):
        k = node[live]
        with np.errstate(invalid="ignore"):
            t0 = (bvh.lo[k] - o[live]) * inv[live]
            t1 = (bvh.hi[k] - o[live]) * inv[live]
        enter = np.maximum(max_along(np.minimum(t0, t1)), lo_t[live])
        leave = np.minimum(min_along(np.maximum(t0, t1)), best[live])
        meets = enter <= leave
        count = np.where(meets, bvh.count[k], 0)
        inner = meets & (bvh.first[k] < 0)
        if count.any():
            ray = np.repeat(np.arange(len(live)), count)
            slot = np.repeat(bvh.first[k], count) + np.arange(int(count.sum())) - \
                np.repeat(np.cumsum(count) - count, count)
            which = bvh.order[slot]
            r = live[ray]
            t, u, v = _intersect(positions[which], o[r], d[r])
            # Leaf triangles in order, as the GLSL loop meets them (t < the running best).
            for j in range(int(count.max())):
                sel = np.flatnonzero((slot - np.repeat(bvh.first[k], count)) == j)
                rj = r[sel]
                good = (t[sel] > lo_t[rj]) & (t[sel] < best[rj])
                if accept is not None:
                    good &= accept[which[sel]]
                good = counted_hits(cutout, good, which[sel], u[sel], v[sel], o[rj], d[rj])
                if any_hit:
                    good &= tri[rj] < 0
                g = sel[good]
                best[r[g]], tri[r[g]], bu[r[g]], bv[r[g]] = t[g], which[g], u[g], v[g]
        node[live] = np.where(inner, k + 1, bvh.miss[k])
        done = node[live] < 0
        if any_hit:
            done |= tri[live] >= 0
        live = live[~done]
    t = np.where(tri >= 0, best, np.inf)
    return t, tri, np.where(tri >= 0, bu, 0.0), np.where(tri >= 0, bv, 0.0)


def closest_hits(tris: SceneTriangles, origins, directions, t_min=0.0, t_max=np.inf,
                 ray: int = RAY_DIFFUSE):
    """``raycast.closest_hits`` through the (cached) BVH of ``tris``."""
    return traverse(bvh_of(tris), tris, origins, directions, t_min, t_max, ray=ray)


def occluded(tris: SceneTriangles, origins, directions, max_t, epsilon: float = SHADOW_EPSILON,
             ray: int = RAY_SHADOW):
    """``raycast.occluded`` through the (cached) BVH: any hit with ε < t < max_t − ε."""
    max_t = np.asarray(max_t, dtype=np.float64) - epsilon
    t, _, _, _ = traverse(bvh_of(tris), tris, origins, directions, epsilon, max_t, any_hit=True,
                          ray=ray)
    return np.isfinite(t)

"""Sparse voxel octree over all cascades, rebuilt bottom-up every update (docs/gi_pipeline.md).

Geometry (docs/gi_pipeline.md): the root is the coarsest cascade's cube (``root_origin``,
``root_size`` = res·S); level ℓ has 2^ℓ nodes per axis of size root_size / 2^ℓ; cascade i's
voxels are the leaves at level ℓ_i = log2(res) + (n−1−i), cell c at node
c + (res/2)·(2^(n−1−i) − 1); depth = log2(res) + n − 1. Sampling is node-centred.

Averaging rules, applied from the deepest level up:
* a cascade voxel (leaf): its radiance / albedo / normal, occlusion 1, count = cache voxels
  merged (several voxels landing in one node — not expected — are averaged weighted by count);
* a node with k ≥ 1 present children and no voxel of its own: the plain mean of the children's
  radiance / albedo / normal (not premultiplied, normals not renormalised: their length shows
  the spread), occlusion k/8, count = sum of the children's counts;
* a node with both its own coarser-cascade voxel and children (a mesh without a finer cache):
  each attribute = ½·own + ½·mean of children, occlusion = max(1, k/8) = 1 (the voxel says
  the surface crosses this node at this node's resolution, as any leaf does, so the node is
  as opaque as a leaf), count = own count + children's counts.

Directional (anisotropic) values, kept beside the isotropic ones (Crassin et al. 2011, Gomes
2015 §3.1/§4.15): per node and per face f of ``FACES`` (+x, −x, +y, −y, +z, −z: the side the
viewer is on), the premultiplied r·α, g·α, b·α, α the node shows to a cone coming from that side:
* a leaf: its premultiplied radiance and α = 1 on every face;
* a parent: for face +x (a cone travelling −x), each of its 4 (y, z) columns composites its 2
  children front to back, front = the x = 1 child, c = c_f + (1 − α_f)·c_b,
  α = α_f + (1 − α_f)·α_b (absent child = 0), and the parent takes the mean of the 4 columns;
  likewise for the other faces. A one-voxel wall across x thus stays opaque (α = 1) seen along
  x at every level (isotropic occlusion reads 0.5 there), and a node straddling the wall shows
  each side only what lies in front of the wall;
* a parent that is also a coarser cascade's voxel: per face, ½·own + ½·the children's
  composited colour, α = 1 (the isotropic ½ : ½ rule face by face).
Known limits (thin-wall test, 2 cm wall in 7 cm voxels): a one-node wall sampled one node
apart composites to α ≥ 0.75 only, and a cone wider than its distance to the wall samples
nodes on both sides (the trilinear filter reaches a whole node past its point). The cone
tracer answers these with ``ConeSettings.transmittance_exponent`` and ``radiance_detail``,
and weighs the faces' colours by optical depth (``svo_sampling.trilinear_directional``), so
edge-on faces behind a wall opaque along x no longer show with weight 1 − d_x².
``one_sided_leaves`` (off here; on in ``gi_update.GISettings``) hides the back of lit voxels.

Storage: levels 0..dense_depth are ``DenseLevel`` 3D arrays indexed [x, y, z] (the mips);
deeper levels are ``SparseLevel`` arrays sorted by Morton key (see ``morton``). Child links:
``child_mask`` bit o is set when child octant o = z<<2 | y<<1 | x is present, and the child is
row ``child_base + popcount(child_mask & ((1 << o) − 1))`` of the next level (children are
contiguous there because keys are sorted). The last dense level carries these links as dense
arrays (−1 / 0 for absent nodes), the index map into the sparse part.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np

from . import svo_sampling as sampling
from .morton import morton_decode, morton_encode
from .svo_sampling import FACES, DenseLevel, SparseLevel

__all__ = ["VoxelOctree", "DenseLevel", "SparseLevel", "LevelStats", "build_octree", "FACES"]

# A sparse level also gets an int32 row map over its window of ≤ res³ nodes when the window
# has at most this many cells (128³ → 8 MB), turning sample()'s searchsorted into one gather.
DEFAULT_MAX_INDEX_WINDOW = 128 ** 3


class LevelStats(NamedTuple):
    level: int
    kind: str    # 'dense' or 'sparse'
    nodes: int   # present nodes
    bytes: int   # all arrays of the level, sampling table and index map included


@dataclass(eq=False)
class VoxelOctree:
    """The octree of one update. levels[ℓ] for ℓ = 0..depth; levels ≤ dense_depth are dense.

    root_origin : (3,) float64 metres; root_size : metres; resolution : cascade res;
    cascade_levels : ℓ_i per cascade index i (finest first); cascade_offsets : node offset of
    cascade i's cell (0, 0, 0) at level ℓ_i.
    emission : the octree of the same voxels with their emission alone as radiance (same
    nodes, same occlusion), when the radiance it was built from carried an ``emission`` part
    (``light_injection.InjectedRadiance``); None when nothing emits. The tracers subtract its
    samples where a cone must not see emission (``conetrace.march_cones``' ``subtract``).
    Built on first use (``emission_build``): only the cones read it, and a posed update of
    the default Accurate quality, which traces triangles, paid its whole build (7–8 of the
    rig's 15.6 ms octree stage beside a glowing panel) for nothing.
    """

    root_origin: np.ndarray
    root_size: float
    depth: int
    dense_depth: int
    resolution: int
    cascade_levels: tuple[int, ...]
    cascade_offsets: tuple[int, ...]
    levels: list = field(repr=False)
    emission_build: "Callable[[], VoxelOctree] | None" = field(default=None, repr=False)

    @functools.cached_property
    def emission(self) -> "VoxelOctree | None":
        return None if self.emission_build is None else self.emission_build()

    def node_size(self, level) -> float | np.ndarray:
        """Edge in metres of a node at ``level`` (int or array)."""
        return self.root_size / np.exp2(level)

    def stats(self) -> list[LevelStats]:
        out = []
        for lv in self.levels:
            arrays = [a for a in vars(lv).values() if isinstance(a, np.ndarray)]
            out.append(LevelStats(lv.level, lv.kind, lv.node_count, sum(a.nbytes for a in arrays)))
        return out

    def lookup(self, level: int, nodes: np.ndarray):
        """Node values at one level.

        nodes : (N, 3) int64 node coordinates (any value; outside the level = absent).
        Returns radiance (N, 3) float32 (not premultiplied), occlusion (N,) float32 and
        present (N,) bool; absent nodes give zeros.
        """
        lv = self.levels[level]
        nodes = np.asarray(nodes, dtype=np.int64).reshape(-1, 3)
        rows = lv.rows(nodes)
        present = rows < lv.table.shape[1] - 1
        radiance = np.zeros((len(nodes), 3), np.float32)
        occlusion = np.zeros(len(nodes), np.float32)
        radiance[present] = lv.radiance.reshape(-1, 3)[rows[present]]
        occlusion[present] = lv.occlusion.reshape(-1)[rows[present]]
        return radiance, occlusion, present

    def finest_level_at(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) float64 world points → (N,) int64: the leaf level ℓ_i of the finest cascade
        whose cube contains the point (the deepest level with nodes there); −1 outside the root."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        x, y, z = ((p[:, a] - self.root_origin[a]) / self.root_size for a in range(3))
        u_min, u_max = np.minimum(np.minimum(x, y), z), np.maximum(np.maximum(x, y), z)
        out = np.full(len(p), -1, dtype=np.int64)
        for ell, off in sorted(zip(self.cascade_levels, self.cascade_offsets)):
            # Cascade cube in root units, [off, off + res) / 2^ℓ: dyadic, so the test is exact.
            inside = (u_min >= off / 2.0 ** ell) & (u_max < (off + self.resolution) / 2.0 ** ell)
            out[inside] = ell
        return out

    def sample(self, points: np.ndarray, level) -> tuple[np.ndarray, np.ndarray]:
        """Node-centred trilinear sample within floor/ceil levels, blended linearly between them.

        points : (N, 3) float64 world metres; level : (N,) float (or scalar), clipped to
        [0, depth]. Returns premultiplied radiance (N, 3) float32 and occlusion (N,) float32.
        Levels deeper than ``finest_level_at(points)`` hold no nodes there and sample 0: the
        caller clamps to it. Points are processed level by level in chunks of
        ``svo_sampling.CHUNK_POINTS``.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = sampling.sample_levels(self.levels, p, level, self.root_origin, self.root_size)
        return np.ascontiguousarray(out[:3].T), out[3]

    def sample_directional(self, points: np.ndarray, level, dirs: np.ndarray,
                           extinction: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Anisotropic sample for cones travelling along ``dirs`` (Crassin 2011, Gomes §4.15).

        points : (N, 3) float64; level : (N,) float (or scalar) as in ``sample``; dirs : (N, 3)
        unit cone directions. Per axis a, the face that faces the cone is read (d_a < 0, the
        cone travelling −a, reads the face seen from +a, etc.) with node-centred trilinear
        interpolation, and the three axes are weighted by d_a² (sum 1 for a unit direction, so
        a direction-independent volume samples exactly as ``sample`` when ``extinction`` is
        False). extinction : combine the axes' occlusion as 1 − Π (1 − α_a)^|d_a| (see
        ``svo_sampling.trilinear_directional``). Levels are blended as in ``sample``.
        Returns premultiplied radiance (N, 3) float32 and occlusion (N,) float32.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        if len(d) != len(p):
            raise ValueError("need one direction per point")
        out = sampling.sample_levels(self.levels, p, level, self.root_origin, self.root_size,
                                     dirs=d, extinction=extinction)
        return np.ascontiguousarray(out[:3].T), out[3]

    def lookup_directional(self, level: int, nodes: np.ndarray) -> np.ndarray:
        """(N, 3) int64 node coordinates → (N, 6, 4) float32 directional values: faces in
        ``FACES`` order, channels r·α, g·α, b·α, α (premultiplied); absent nodes give zeros."""
        lv = self.levels[level]
        rows = lv.directional_columns(lv.rows(np.asarray(nodes, dtype=np.int64).reshape(-1, 3)))
        return lv.directional[:, rows].T.reshape(-1, len(FACES), 4).astype(np.float32)


@dataclass
class _Nodes:
    """One level during the build: present nodes sorted by Morton key."""

    keys: np.ndarray       # (M,) uint64
    radiance: np.ndarray   # (M, 3) float32
    albedo: np.ndarray     # (M, 3) float32
    normal: np.ndarray     # (M, 3) float32
    occlusion: np.ndarray  # (M,) float32
    count: np.ndarray      # (M,) int32
    child_mask: np.ndarray  # (M,) uint8
    # (24, M) premultiplied directional values, row 4·f + c = channel c (r·α, g·α, b·α, α) of
    # face f of FACES: channel-major like the sampling tables, so that every numpy loop of the
    # build runs over M (an (M, 6, 4) layout made them loop over 4 channels at a time);
    # None = direction-independent (leaves): every face is the isotropic premultiplied value.
    directional: np.ndarray | None = None

    ATTRS: ClassVar[tuple[str, ...]] = ("radiance", "albedo", "normal")

    @classmethod
    def empty(cls) -> "_Nodes":
        z3 = np.zeros((0, 3), np.float32)
        return cls(np.zeros(0, np.uint64), z3, z3, z3, np.zeros(0, np.float32),
                   np.zeros(0, np.int32), np.zeros(0, np.uint8))

    def premultiplied(self) -> np.ndarray:
        """(M, 4) float32 isotropic r·α, g·α, b·α, α."""
        return np.concatenate([self.radiance * self.occlusion[:, None],
                               self.occlusion[:, None]], axis=1).astype(np.float32)

    def all_faces(self) -> np.ndarray:
        """(24, M) float32 directional values, row 4·f + c (leaves: the isotropic value on
        every face)."""
        if self.directional is None:
            return np.tile(self.premultiplied().T, (len(FACES), 1))
        return self.directional


# Face f = 2·axis + s of FACES: its axis, the sign of its viewer direction, and the octants
# (z<<2 | y<<1 | x) of the 4 front and the 4 back children of its columns (front = bit
# ``axis`` of the octant is 1 − s), columns in the order of the other two axes (z, y, x).
_FACE_AXES = np.repeat(np.arange(3), 2)
_FACE_SIGNS = np.tile(np.array([1.0, -1.0], np.float32), 3)[:, None]
_OCTANTS = np.arange(8).reshape(2, 2, 2)  # [z, y, x]
_FRONT = np.array([np.take(_OCTANTS, 1 - f % 2, axis=2 - f // 2).ravel()
                   for f in range(len(FACES))])
_BACK = np.array([np.take(_OCTANTS, f % 2, axis=2 - f // 2).ravel() for f in range(len(FACES))])


def _one_sided_faces(nodes: _Nodes) -> np.ndarray:
    """(24, M) leaf faces of ``build_octree(one_sided_leaves=True)``.

    A surface voxel emits into its normal's hemisphere only: face f (viewer direction v_f, a
    unit axis) shows radiance × clip(1 + n·v_f, 0, 1) and α = 1. The back (n·v = −1) is black
    but opaque; faces seen edge-on (n·v = 0) and from the front keep the full radiance, so a
    surface viewed from its front side samples exactly as with isotropic leaves. A voxel whose
    normal is short (opposite faces averaged into it) is attenuated little: it cannot tell.
    """
    m = len(nodes.keys)
    weight = nodes.normal.T[_FACE_AXES]  # (6, M): face f views along axis f // 2
    weight *= _FACE_SIGNS  # n·v
    weight += 1.0
    np.clip(weight, 0.0, 1.0, out=weight)
    faces = np.empty((len(FACES), 4, m), np.float32)
    np.multiply((nodes.radiance * nodes.occlusion[:, None]).T[None], weight[:, None],
                out=faces[:, :3])
    faces[:, 3] = nodes.occlusion
    return faces.reshape(4 * len(FACES), m)


def _group_starts(sorted_keys: np.ndarray) -> np.ndarray:
    """Start index of each run of equal values in a sorted array."""
    if len(sorted_keys) == 0:
        return np.zeros(0, np.int64)
    return np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])


def _leaf_nodes(cells, radiance, albedo, normal, count, offset: int,
                one_sided: bool = False) -> _Nodes:
    """A cascade's voxels as leaves: occlusion 1; voxels sharing a node average by count.
    Directional faces: isotropic (None), or ``_one_sided_faces`` when ``one_sided``."""
    keys = morton_encode(np.asarray(cells, np.int64).reshape(-1, 3) + offset)
    if len(keys) == 0:
        return _Nodes.empty()
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    starts = _group_starts(keys)
    attrs = [np.asarray(v, np.float32).reshape(-1, 3)[order] for v in (radiance, albedo, normal)]
    if len(starts) < len(keys):  # cells are unique by contract; merge duplicates anyway
        count = np.asarray(count, np.int64)[order]
        weight = np.maximum(count, 1).astype(np.float64)[:, None]
        total = np.add.reduceat(weight, starts, axis=0)
        attrs = [(np.add.reduceat(a * weight, starts, axis=0) / total).astype(np.float32)
                 for a in attrs]
        keys, count = keys[starts], np.add.reduceat(count, starts).astype(np.int32)
    else:
        count = np.asarray(count)[order].astype(np.int32)
    m = len(keys)
    leaves = _Nodes(keys, *attrs, np.ones(m, np.float32), count, np.zeros(m, np.uint8))
    if one_sided:
        leaves.directional = _one_sided_faces(leaves)
    return leaves


def _parents(children: _Nodes) -> _Nodes:
    """Average present children into their parents: mean attributes, occlusion k/8, and the
    directional values of ``_directional_parents``."""
    if len(children.keys) == 0:
        return _Nodes.empty()
    parent_keys = children.keys >> np.uint64(3)
    starts = _group_starts(parent_keys)
    k = np.diff(np.r_[starts, len(parent_keys)])
    attrs = [np.add.reduceat(getattr(children, a), starts, axis=0) / k[:, None].astype(np.float32)
             for a in _Nodes.ATTRS]
    octants = (children.keys & np.uint64(7)).astype(np.uint8)
    octant_bits = np.left_shift(1, octants, dtype=np.uint8)
    groups = np.repeat(np.arange(len(starts)), k)
    return _Nodes(parent_keys[starts], *attrs, (k / 8).astype(np.float32),
                  np.add.reduceat(children.count, starts).astype(np.int32),
                  np.bitwise_or.reduceat(octant_bits, starts),
                  _directional_parents(children, groups, octants, len(starts)))


def _directional_parents(children: _Nodes, groups: np.ndarray, octants: np.ndarray,
                         parents: int) -> np.ndarray:
    """(24, P) directional values of the parents (Crassin et al. 2011; Gomes 2015 §4.15).

    For face f = 2·axis + s (viewer on the +axis side for s = 0, the −axis side for s = 1),
    each of the 4 columns of two children along ``axis`` is composited front to back with the
    children's own face-f values, front = the child nearer the viewer (bit ``axis`` of the
    octant = 1 − s): c = c_f + (1 − α_f)·c_b, α = α_f + (1 − α_f)·α_b, absent children 0; the
    parent's value is the mean of the 4 columns (summed in ``_FRONT``'s order). groups : (M,)
    parent index of each child; octants : (M,) z<<2 | y<<1 | x. All faces at once on a
    channel-major (6, 4, 8, P) scatter: every operation then loops over P.
    """
    full = np.zeros((4 * len(FACES), 8 * parents), np.float32)
    full[:, octants.astype(np.intp) * parents + groups] = children.all_faces()
    full = full.reshape(len(FACES), 4, 8, parents)  # [face, channel, octant, parent]
    faces = np.arange(len(FACES))[:, None]
    front = full[faces, :, _FRONT]  # (6, 4 columns, 4 channels, P)
    column = full[faces, :, _BACK]
    column *= 1.0 - front[:, :, 3:4]  # in place: the same products and sums, fewer temporaries
    column += front
    return column.mean(axis=1).reshape(4 * len(FACES), parents)


def _merge_own(own: _Nodes, parents: _Nodes) -> _Nodes:
    """Union of a coarser cascade's voxels and averaged parents at one level (rule ½ : ½)."""
    keys = np.union1d(own.keys, parents.keys)
    m = len(keys)
    i_own = np.searchsorted(keys, own.keys)
    i_par = np.searchsorted(keys, parents.keys)
    has_children = np.zeros(m, bool)
    has_children[i_par] = True
    both = has_children[i_own][:, None]
    attrs = []
    for a in _Nodes.ATTRS:
        merged = np.zeros((m, 3), np.float32)
        merged[i_par] = getattr(parents, a)
        mine = getattr(own, a)
        merged[i_own] = np.where(both, 0.5 * (merged[i_own] + mine), mine)
        attrs.append(merged)
    occlusion = np.zeros(m, np.float32)
    occlusion[i_par] = parents.occlusion
    occlusion[i_own] = 1.0
    count = np.zeros(m, np.int32)
    count[i_par] = parents.count
    count[i_own] += own.count  # i_own holds unique rows, so += is a plain add
    mask = np.zeros(m, np.uint8)
    mask[i_par] = parents.child_mask
    # Directional: a parent alone keeps its faces; a voxel alone is a leaf (α = 1, its radiance
    # on every face); both: each face's colour = ½·own + ½·children's composited colour on that
    # face (un-premultiplied), α = 1 — the isotropic rule applied face by face.
    directional = np.zeros((len(FACES), 4, m), np.float32)
    directional.reshape(4 * len(FACES), m)[:, i_par] = parents.all_faces()
    mine = own.all_faces().reshape(len(FACES), 4, -1)
    children = directional[:, :, i_own]
    colour = children[:, :3] / np.maximum(children[:, 3:4], 1e-30)
    mixed = np.concatenate([0.5 * (colour + mine[:, :3]), np.ones_like(mine[:, 3:])], 1)
    directional[:, :, i_own] = np.where(both[:, 0], mixed, mine)
    return _Nodes(keys, *attrs, occlusion, count, mask, directional.reshape(4 * len(FACES), m))


@dataclass(frozen=True)
class _Frame:
    """Octree geometry derived from the cascade grids (validated against the contract)."""

    root_origin: np.ndarray
    root_size: float
    resolution: int
    levels: tuple[int, ...]   # ℓ_i per cascade index
    offsets: tuple[int, ...]  # node offset of cascade i at ℓ_i

    @property
    def depth(self) -> int:
        return max(self.levels)

    def window(self, level: int) -> tuple[np.ndarray, int]:
        """Origin (3,) and size of the cube of nodes that can be present at ``level``."""
        if level <= min(self.levels):
            return np.zeros(3, np.int64), 1 << level
        offset = self.offsets[self.levels.index(level)]
        return np.full(3, offset, np.int64), self.resolution


def _frame(grids) -> _Frame:
    n = len(grids)
    if n == 0:
        raise ValueError("build_octree needs at least one cascade")
    if sorted(g.index for g in grids) != list(range(n)):
        raise ValueError("cascade indices must be 0..n-1")
    grids = sorted(grids, key=lambda g: g.index)
    res = int(grids[0].resolution)
    if res < 2 or res & (res - 1) or any(int(g.resolution) != res for g in grids):
        raise ValueError("all cascades need the same power-of-two resolution")
    span0 = float(grids[0].span)
    coarse = grids[-1]
    centre = np.asarray(coarse.origin, np.float64) + (res / 2) * float(coarse.span)
    for g in grids:
        span = span0 * 2 ** g.index
        expected = centre - (res / 2) * span
        if (not np.isclose(float(g.span), span, rtol=1e-6)
                or not np.allclose(g.origin, expected, rtol=0, atol=1e-6 * span)):
            raise ValueError(f"cascade {g.index} is not nested as docs/gi_pipeline.md states")
    log_res = res.bit_length() - 1
    return _Frame(np.asarray(coarse.origin, np.float64), res * float(coarse.span), res,
                  tuple(log_res + n - 1 - i for i in range(n)),
                  tuple((res // 2) * (2 ** (n - 1 - i) - 1) for i in range(n)))


def _table(nodes: _Nodes, rows: np.ndarray | None, size: int) -> np.ndarray:
    """(4, size + 1) premultiplied sampling channels r·α, g·α, b·α, α in columns ``rows``
    (None: the first M); unused columns 0."""
    rows = slice(0, len(nodes.keys)) if rows is None else rows
    table = np.zeros((4, size + 1), np.float32)
    table[:3, rows] = (nodes.radiance * nodes.occlusion[:, None]).T
    table[3, rows] = nodes.occlusion
    return table


def _directional_table(nodes: _Nodes) -> np.ndarray:
    """(24, M + 1) directional sampling channels, row 4·f + c = channel c of face f; the
    last column 0."""
    m = len(nodes.keys)
    table = np.empty((4 * len(FACES), m + 1), sampling.DIRECTIONAL_DTYPE)
    table[:, :m] = nodes.all_faces()
    table[:, m] = 0.0
    return table


def _dense_level(level: int, nodes: _Nodes, child_base: np.ndarray | None) -> DenseLevel:
    s = 1 << level
    c = morton_decode(nodes.keys)
    rows = (c[:, 0] * s + c[:, 1]) * s + c[:, 2]
    grids = {}
    for name, width in (("radiance", 3), ("normal", 3), ("albedo", 3), ("occlusion", 0),
                        ("count", 0)):
        values = getattr(nodes, name)
        flat = np.zeros((s ** 3, width) if width else s ** 3, values.dtype)
        flat[rows] = values
        grids[name] = flat.reshape((s, s, s, width) if width else (s, s, s))
    base = mask = None
    if child_base is not None:
        base = np.full(s ** 3, -1, np.int64)
        base[rows] = child_base
        mask = np.zeros(s ** 3, np.uint8)
        mask[rows] = nodes.child_mask
        base, mask = base.reshape(s, s, s), mask.reshape(s, s, s)
    m = len(nodes.keys)
    index = np.full(s ** 3 + 1, m, np.int32)
    index[rows] = np.arange(m, dtype=np.int32)
    return DenseLevel(level=level, child_base=base, child_mask=mask,
                      table=_table(nodes, rows, s ** 3),
                      directional=_directional_table(nodes),
                      directional_index=index, **grids)


def _sparse_level(level: int, nodes: _Nodes, child_base: np.ndarray, frame: _Frame,
                  max_index_window: int) -> SparseLevel:
    m = len(nodes.keys)
    w0, w = frame.window(level)
    index_map = None
    if w ** 3 <= max_index_window:
        rel = morton_decode(nodes.keys) - w0
        index_map = np.full(w ** 3 + 1, m, np.int32)
        index_map[(rel[:, 0] * w + rel[:, 1]) * w + rel[:, 2]] = np.arange(m, dtype=np.int32)
    return SparseLevel(level, nodes.keys, nodes.radiance, nodes.occlusion, nodes.normal,
                       nodes.albedo, nodes.count, child_base, nodes.child_mask, w0, w,
                       index_map, _table(nodes, None, m), _directional_table(nodes))


def build_octree(cascades, radiance, dense_depth: int = 6, *,
                 max_index_window: int = DEFAULT_MAX_INDEX_WINDOW,
                 one_sided_leaves: bool = False) -> VoxelOctree:
    """Build the octree of one update from the cascades' voxels and their outgoing radiance.

    cascades : list of ``CascadeVoxels`` (grid.index/span/resolution/origin, cells (N, 3) int32
    in [0, res), albedo (N, 3), normal (N, 3), count (N,)); radiance : list of (N, 3) float32,
    aligned with ``cascades``. dense_depth : last dense level (clamped to the depth).
    max_index_window : largest window (cells) that gets an int32 index map for sample();
    0 makes sample() use searchsorted on every sparse level. one_sided_leaves : leaves' directional
    faces hide the radiance of their back side (``_one_sided_faces``) instead of showing the
    same value on all 6 faces; the isotropic fields are unaffected. Raises ValueError when the grids
    do not nest as docs/gi_pipeline.md states or an array has the wrong length.
    radiance may carry an ``emission`` attribute (``light_injection.InjectedRadiance``): a list
    aligned with it of the emission part; when any voxel emits, the octree of that part is built
    too (``VoxelOctree.emission``).
    """
    emission = getattr(radiance, "emission", None)
    emission_build = None
    if emission is not None and any(len(e) and np.max(e) > 0 for e in emission):
        emitted = list(emission)

        def emission_build():
            return build_octree(list(cascades), emitted, dense_depth,
                                max_index_window=max_index_window,
                                one_sided_leaves=one_sided_leaves)
    if len(radiance) != len(cascades):
        raise ValueError("need one radiance array per cascade")
    frame = _frame([c.grid for c in cascades])
    own = {}
    for cv, rad in zip(cascades, radiance):
        n = len(cv.cells)
        if any(len(a) != n for a in (rad, cv.albedo, cv.normal, cv.count)):
            raise ValueError(f"cascade {cv.grid.index}: attribute lengths differ from cells")
        if n and (np.min(cv.cells) < 0 or np.max(cv.cells) >= frame.resolution):
            raise ValueError(f"cascade {cv.grid.index}: cells outside [0, resolution)")
        own[frame.levels[cv.grid.index]] = _leaf_nodes(
            cv.cells, rad, cv.albedo, cv.normal, cv.count, frame.offsets[cv.grid.index],
            one_sided_leaves)
    depth, dense_depth = frame.depth, max(0, min(int(dense_depth), frame.depth))
    nodes = [None] * (depth + 1)
    nodes[depth] = own[depth]
    for ell in range(depth - 1, -1, -1):
        nodes[ell] = _parents(nodes[ell + 1])
        if ell in own and len(own[ell].keys):
            nodes[ell] = _merge_own(own[ell], nodes[ell])
    levels = []
    for ell, nd in enumerate(nodes):
        base = None  # child links: from the last dense level down
        if dense_depth <= ell < depth:
            base = np.searchsorted(nodes[ell + 1].keys, nd.keys << np.uint64(3)).astype(np.int64)
        if ell <= dense_depth:
            levels.append(_dense_level(ell, nd, base))
        else:
            base = np.zeros(len(nd.keys), np.int64) if base is None else base  # deepest level
            levels.append(_sparse_level(ell, nd, base, frame, max_index_window))
    return VoxelOctree(frame.root_origin, frame.root_size, depth, dense_depth, frame.resolution,
                       frame.levels, frame.offsets, levels, emission_build)

"""The threaded BVH (voxgi_addon/bvh.py): build invariants, numpy traversal against brute force
and the grid ray caster, packing, and the shared sample patterns (voxgi_addon/sampling.py)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import box, uv_sphere
from snapshots import mesh, snapshot, translation

from voxgi.voxgi_addon.gi.sampling import hammersley, hashed_square, pcg_hash, radical_inverse
from voxgi.voxgi_addon.scene import bvh as bvh_module
from voxgi.voxgi_addon.scene.bvh import (
    MAX_LEAF,
    NODE_TEXELS,
    ORDERED_BYTES,
    ORDERS,
    TEXTURE_WIDTH,
    TRIANGLE_TEXELS,
    build_bvh,
    pack_bvh,
    traverse,
)
from voxgi.voxgi_addon.scene.geometry import SceneTriangles, world_triangles
from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded
from voxgi.voxgi_addon.scene.snapshot import ObjectData


def soup(positions):
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3, 3)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return SceneTriangles(p, n, np.arange(len(p), dtype=np.int32) % 3, np.zeros(len(p), np.int32))


def random_soup(rng, count, spread=2.0, size=0.3):
    centres = rng.uniform(-spread, spread, (count, 1, 3))
    return soup(centres + rng.normal(scale=size, size=(count, 3, 3)))


def random_rays(rng, count, spread=3.0):
    o = rng.uniform(-spread, spread, (count, 3))
    d = rng.normal(size=(count, 3))
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def brute_force(tris, o, d, t_min=0.0, t_max=np.inf):
    """Every ray against every triangle, float64 double-sided Möller–Trumbore."""
    p = tris.positions
    v0, e1, e2 = p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    best_t = np.full(len(o), np.inf)
    best_tri = np.full(len(o), -1)
    for i in range(len(o)):
        pv = np.cross(d[i], e2)
        det = (e1 * pv).sum(1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o[i] - v0
            u = (s * pv).sum(1) * inv
            q = np.cross(s, e1)
            v = (d[i] * q).sum(1) * inv
            t = (e2 * q).sum(1) * inv
        ok = (np.abs(det) > 1e-12 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)) & \
            (u >= 0) & (v >= 0) & (u + v <= 1) & (t > t_min) & (t < t_max)
        if ok.any():
            j = np.flatnonzero(ok)[np.argmin(t[ok])]
            best_t[i], best_tri[i] = t[j], j
    return best_t, best_tri


def check_invariants(bvh, tris):
    n, t = len(bvh), len(tris)
    leaf = bvh.first >= 0
    # Every triangle sits in exactly one leaf, leaves are small.
    assert sorted(bvh.order.tolist()) == list(range(t))
    assert bvh.count[leaf].sum() == t and (bvh.count[leaf] <= MAX_LEAF).all()
    assert (bvh.count[~leaf] == 0).all()
    covered = np.concatenate([np.arange(f, f + c) for f, c in zip(bvh.first[leaf], bvh.count[leaf])])
    assert sorted(covered.tolist()) == list(range(t))
    # Threading: the miss link of a node skips exactly its subtree; children nest in parents.
    size = np.where(bvh.miss >= 0, bvh.miss, n) - np.arange(n)
    assert (size >= 1).all() and (size[leaf] == 1).all()
    for i in np.flatnonzero(~leaf):
        left = i + 1
        right = bvh.miss[left]
        assert right == left + size[left] and bvh.miss[right] == bvh.miss[i]
        for child in (left, right):
            assert (bvh.lo[child] >= bvh.lo[i] - 1e-12).all()
            assert (bvh.hi[child] <= bvh.hi[i] + 1e-12).all()
    # Leaves bound their triangles.
    p = tris.positions
    for i in np.flatnonzero(leaf):
        corners = p[bvh.order[bvh.first[i]:bvh.first[i] + bvh.count[i]]].reshape(-1, 3)
        assert (corners >= bvh.lo[i]).all() and (corners <= bvh.hi[i]).all()


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 300), st.integers(0, 2**31 - 1))
def test_build_invariants_and_traversal_equal_brute_force(count, seed):
    rng = np.random.default_rng(seed)
    tris = random_soup(rng, count)
    bvh = build_bvh(tris)
    check_invariants(bvh, tris)
    o, d = random_rays(rng, 64)
    t, tri, u, v = traverse(bvh, tris, o, d)
    ref_t, ref_tri = brute_force(tris, o, d)
    np.testing.assert_array_equal(np.isfinite(t), np.isfinite(ref_t))
    np.testing.assert_allclose(t[np.isfinite(t)], ref_t[np.isfinite(ref_t)], rtol=1e-9)
    same = tri == ref_tri
    assert same.mean() >= 0.98  # a tie on a shared edge may pick either triangle
    # The barycentrics put the hit on the triangle at distance t.
    hit = tri >= 0
    p = tris.positions[tri[hit]]
    point = p[:, 0] + u[hit, None] * (p[:, 1] - p[:, 0]) + v[hit, None] * (p[:, 2] - p[:, 0])
    np.testing.assert_allclose(point, o[hit] + t[hit, None] * d[hit], atol=1e-9)


def test_degenerate_inputs_build():
    empty = soup(np.zeros((0, 3, 3)))
    bvh = build_bvh(empty)
    assert len(bvh) == 1 and bvh.count[0] == 0 and bvh.miss[0] == -1
    t, tri, _, _ = traverse(bvh, empty, np.zeros((3, 3)), np.eye(3))
    assert np.isinf(t).all() and (tri == -1).all()
    packed = pack_bvh(bvh, empty)
    assert bvh_module.leaf_codes(packed.nodes[0, 1, 3]) == 0  # an empty leaf
    # 40 copies of one triangle: centroids coincide, the build splits at the median.
    same = soup(np.repeat([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], 40, axis=0))
    bvh = build_bvh(same)
    check_invariants(bvh, same)
    t, tri, _, _ = traverse(bvh, same, [[0.2, 0.2, 1.0]], [[0, 0, -1.0]])
    assert t[0] == pytest.approx(1.0) and tri[0] >= 0


def test_traversal_equals_the_grid_ray_caster_on_a_scene():
    """Box + sphere scene: the BVH's closest hits and shadow rays equal raycast's."""
    scene = snapshot(
        meshes=[mesh("box", *box((2.0, 2.0, 2.0), (0.0, 0.0, 1.0))),
                mesh("sphere", *uv_sphere(12, 16, 0.4))],
        objects=[ObjectData("Box", "box", np.eye(4)),
                 ObjectData("Ball", "sphere", translation(0.2, 0.1, 0.6))],
    )
    tris = world_triangles(scene)
    rng = np.random.default_rng(3)
    o = rng.uniform(-0.9, 0.9, (2000, 3)) + [0, 0, 1]
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, tri, u, v = bvh_module.closest_hits(tris, o, d, 1e-4)
    rt, rtri, ru, rv = closest_hits(tris, o, d, 1e-4)
    assert (tri == rtri).mean() > 0.995
    np.testing.assert_allclose(t, rt, rtol=1e-9)
    same = tri == rtri
    np.testing.assert_allclose(u[same], ru[same], atol=1e-9)
    np.testing.assert_allclose(v[same], rv[same], atol=1e-9)
    max_t = rng.uniform(0.1, 2.0, len(o))
    np.testing.assert_array_equal(bvh_module.occluded(tris, o, d, max_t),
                                  occluded(tris, o, d, max_t))


def _layout(packed, layout: int, bvh):
    """Layout ``layout`` of ``packed``'s node texels read back as a ``BVH`` (the order's)."""
    rows = packed.nodes.shape[0] // ORDERS
    texels = packed.nodes[layout * rows:(layout + 1) * rows].reshape(-1, NODE_TEXELS, 4)
    texels = texels[:packed.node_count]
    code = bvh_module.leaf_codes(texels[:, 1, 3])
    miss = texels[:, 0, 3].astype(np.int32)
    return bvh_module.BVH(lo=texels[:, 0, :3].astype(np.float64), hi=texels[:, 1, :3].astype(np.float64),
                          miss=miss, first=np.where(code >= 0, code >> 4, -1).astype(np.int32),
                          count=np.where(code >= 0, code & 15, 0).astype(np.int32), order=bvh.order,
                          depth=bvh.depth)


def test_packing_layout():
    rng = np.random.default_rng(1)
    tris = random_soup(rng, 50)
    bvh = build_bvh(tris)
    packed = pack_bvh(bvh, tris, layouts=1)  # the BVH's own depth-first order
    nodes = packed.nodes.reshape(-1, 4)
    tri = packed.triangles.reshape(-1, 4)
    assert packed.nodes.shape[1:] == (TEXTURE_WIDTH, 4) and packed.nodes.dtype == np.float32
    assert packed.node_count == len(bvh) and packed.triangle_count == 50
    k = np.arange(len(bvh))
    np.testing.assert_array_equal(nodes[NODE_TEXELS * k, 3], bvh.miss)
    code = bvh_module.leaf_codes(nodes[NODE_TEXELS * k + 1, 3])
    leaf = bvh.first >= 0
    np.testing.assert_array_equal(code[~leaf], -1)
    np.testing.assert_array_equal(code[leaf] >> 4, bvh.first[leaf])
    np.testing.assert_array_equal(code[leaf] & 15, bvh.count[leaf])
    j = np.arange(50)
    original = tri[TRIANGLE_TEXELS * j + 1, 3].astype(np.int64)
    np.testing.assert_array_equal(original, bvh.order)
    np.testing.assert_allclose(tri[TRIANGLE_TEXELS * j, :3], tris.positions[bvh.order, 0], atol=1e-6)
    np.testing.assert_array_equal(tri[TRIANGLE_TEXELS * j, 3], tris.materials[bvh.order])
    normals = packed.normals.reshape(-1, 4)
    np.testing.assert_allclose(normals[TRIANGLE_TEXELS * j + 2, :3], tris.normals[bvh.order], atol=1e-6)


def test_each_ray_direction_has_a_layout_with_the_nearer_child_first_and_the_same_hits():
    """``pack_bvh`` packs ``ORDERS`` layouts of one BVH (a small one fits ``ORDERED_BYTES``):
    in layout 2a + s every interior node's first child lies first along axis a toward +a
    (s = 0) or −a (s = 1), and each layout, read back from its texels and traversed, finds
    exactly the hits of the BVH itself (the GPU picks one by each ray's direction)."""
    rng = np.random.default_rng(5)
    tris = random_soup(rng, 300)
    bvh = build_bvh(tris)
    packed = pack_bvh(bvh, tris)
    assert bvh_module.node_layouts(len(bvh)) == ORDERS
    assert packed.nodes.shape[0] == ORDERS * max(1, -(-NODE_TEXELS * len(bvh) // TEXTURE_WIDTH))
    o = rng.uniform(-1.5, 1.5, (400, 3))
    d = rng.normal(size=(400, 3))
    expected = traverse(bvh, tris, o, d)
    for layout in range(ORDERS):
        laid = _layout(packed, layout, bvh)
        axis, sign = layout // 2, (1.0, -1.0)[layout % 2]
        inner = np.flatnonzero(laid.first < 0)
        near, far = inner + 1, laid.miss[inner + 1]
        centre = (laid.lo + laid.hi)[:, axis] * sign
        assert (centre[near] <= centre[far]).all()
        got = traverse(laid, tris, o, d)
        np.testing.assert_array_equal(got[1], expected[1])
        np.testing.assert_allclose(got[0], expected[0])
    # past ORDERED_BYTES one layout, the BVH's own, its rows one more than a multiple of ORDERS
    assert bvh_module.node_layouts(ORDERED_BYTES // 16) == 1
    one = pack_bvh(bvh, tris, layouts=1).nodes
    assert one.shape[0] % ORDERS == 1



def test_build_of_100k_triangles_is_balanced():
    """A 100k-triangle soup builds a tree a traversal can use: shallow, every triangle in
    exactly one leaf, leaves no larger than MAX_LEAF. (Its build time is measured by ``make
    bench``, not asserted here: the machines are shared.)"""
    from voxgi.voxgi_addon.scene.bvh import MAX_LEAF
    rng = np.random.default_rng(0)
    tris = random_soup(rng, 100_000, spread=5.0, size=0.05)
    bvh = build_bvh(tris)
    assert bvh.depth < 40
    leaves = bvh.count > 0
    assert bvh.count[leaves].max() <= MAX_LEAF
    np.testing.assert_array_equal(np.sort(bvh.order), np.arange(100_000))
    assert bvh.count[leaves].sum() == 100_000


def test_sample_patterns():
    # Known PCG hash values (the GLSL port is checked against these on the GPU lane).
    np.testing.assert_array_equal(pcg_hash(np.array([0, 1, 2], np.uint32)),
                                  np.array([129708002, 2831084092, 2055130248], np.uint32))
    assert radical_inverse(np.array([1, 2, 3]))[0] == 0.5
    np.testing.assert_allclose(radical_inverse(np.array([1, 2, 3])), [0.5, 0.25, 0.75])
    s = hashed_square(np.arange(100), 3, 16)
    assert s.shape == (100, 16, 2) and (s >= 0).all() and (s < 1).all()
    cells = np.floor(s * 4).astype(int)
    for k in range(16):  # stratum k = (k // 4, k % 4)
        assert (cells[:, k, 0] == k // 4).all() and (cells[:, k, 1] == k % 4).all()
    np.testing.assert_array_equal(hashed_square(np.arange(5), 3, 16), hashed_square(np.arange(5), 3, 16))
    assert not np.array_equal(hashed_square(np.arange(5), 3, 16), hashed_square(np.arange(5), 4, 16))
    h = hammersley(np.arange(1000), 0, 8)
    assert h.shape == (1000, 8, 2)
    # One point per eighth of x after the rotation, per pixel.
    assert (np.sort(np.floor(((h[..., 0] - h[:, :1, 0]) % 1.0) * 8 + 1e-9), axis=1) == np.arange(8)).all()
    assert abs(h.mean() - 0.5) < 0.01


def test_a_triangle_with_a_nan_or_infinite_corner_hides_none_beside_it():
    """A triangle with a NaN or infinite corner (a broken import) is hit by no ray, and the
    triangles that share its nodes are hit as the grid ray caster hits them. (Its box once made
    its nodes' bounds NaN, up to the root: every ray missed the whole scene.)"""
    rng = np.random.default_rng(5)
    positions = rng.uniform(-1.0, 1.0, (120, 3, 3))
    positions[7, 1, 0] = np.nan
    positions[21, 0, 2] = np.inf
    positions[40, 2, 1] = -np.inf
    tris = soup(positions)
    bvh = build_bvh(tris)
    assert np.isfinite(bvh.lo).all() and np.isfinite(bvh.hi).all()
    o = rng.uniform(-0.5, 0.5, (2000, 3)) + [0, 0, 3]
    d = rng.uniform(-0.5, 0.5, (2000, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, tri, _, _ = bvh_module.closest_hits(tris, o, d, 1e-4)
    rt, rtri, _, _ = closest_hits(tris, o, d, 1e-4)
    assert (rtri >= 0).mean() > 0.5  # the rays meet the soup
    np.testing.assert_array_equal(tri, rtri)
    np.testing.assert_allclose(t, rt, rtol=1e-9)
    assert not np.isin(tri, [7, 21, 40]).any()

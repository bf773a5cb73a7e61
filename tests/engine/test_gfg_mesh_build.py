"""GFG data-type codecs, single-indexed mesh building, canonical skin weights, node transforms."""
import numpy as np
import pytest
from meshes import box, uv_sphere

from voxgi.voxgi_addon.files.gfg import Node, VertexTypes, build_mesh, canonical_skin, compose_world, mesh_arrays
from voxgi.voxgi_addon.files.gfg import data_types as dt
from voxgi.voxgi_addon.files.gfg.mesh_build import NORMAL_TYPES, POSITION_TYPES, UV_TYPES
from voxgi.voxgi_addon.files.gfg.model import GFGScene
from voxgi.voxgi_addon.files.gfg.spec import Logic
from voxgi.voxgi_addon.files.gfg.transforms import euler_xyz_matrix
from voxgi.voxgi_addon.files.gfg.writer import to_bytes

SUPPORTED = sorted(c for c in range(83) if dt.data_type(c) is not None)


def _sample(code, rng, n=500):
    kind = dt.data_type(code)
    if kind.name == "UINT_2_10_10_10":
        return np.column_stack([rng.integers(0, 1024, (n, 3)), rng.integers(0, 4, n)])
    if kind.name == "UINT_10F_11F_11F":
        return rng.uniform(0, 100, (n, 3)) ** rng.uniform(-3, 1, (n, 1))
    if kind.name == "CUSTOM_1_15N_16N":
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    if kind.kind == "int":
        info = np.iinfo(kind.base)
        return rng.integers(max(info.min, -1000), min(info.max, 1000), (n, kind.components))
    width = 4 if kind.kind == "packed" else kind.components
    return rng.uniform(-1.2, 1.2, (n, width))


@pytest.mark.parametrize("code", SUPPORTED, ids=dt.name_of)
def test_decoding_then_encoding_gives_the_same_storage(code):
    rng = np.random.default_rng(code)
    stored = dt.encode(_sample(code, rng), code)
    assert stored.dtype == dt.data_type(code).base and stored.shape[1] == dt.data_type(code).components
    assert np.array_equal(dt.encode(dt.decode(stored, code), code), stored)


def test_codecs_are_accurate_to_their_precision():
    rng = np.random.default_rng(1)
    unit = rng.normal(size=(1000, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    # CUSTOM_1_15N_16N rebuilds z = ±sqrt(1 - x² - y²), which amplifies rounding near z = 0.
    for name, tol in (("NORM_2_10_10_10", 1 / 511), ("CUSTOM_1_15N_16N", 1e-2), ("NORM16_4", 1 / 32767)):
        code = dt.code_of(name)
        back = dt.decode(dt.encode(unit, code), code)[:, :3]
        assert np.abs(back - unit).max() <= tol, name
    # The original packer scaled x and y differently from its unpacker; ours round-trips both.
    code = dt.code_of("CUSTOM_1_15N_16N")
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, -1], [0.6, -0.8, 0]])
    assert np.allclose(dt.decode(dt.encode(axes, code), code), axes, atol=1e-2)
    rgb = np.array([[0.0, 1.0, 2.5], [65000.0, 1e-3, 0.25]])
    packed = dt.decode(dt.encode(rgb, dt.code_of("UINT_10F_11F_11F")), dt.code_of("UINT_10F_11F_11F"))
    assert np.allclose(packed, rgb, rtol=1 / 32) and packed[0, 1] == 1.0


def _flat_corner_normals(v, t):
    p = v[t]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return np.repeat((n / np.linalg.norm(n, axis=1, keepdims=True))[:, None], 3, 1).astype(np.float32)


def test_corners_that_agree_share_a_vertex_and_slots_become_ranges():
    v, t = box()
    slots = np.array([1, 0] * 6)
    mesh = build_mesh("Box", v, t, corner_normals=_flat_corner_normals(v, t), triangle_slots=slots,
                      slot_materials=[5, -1])
    assert mesh.vertex_count == 24  # 6 flat faces × 4 corners
    assert [(r.material, r.index_offset, r.index_count) for r in mesh.ranges] == [(5, 0, 18), (-1, 18, 18)]
    assert mesh.indices.dtype == np.uint16
    a = mesh_arrays(mesh)
    assert np.array_equal(a.positions[a.triangles], v.astype(np.float32)[t[np.argsort(slots, kind="stable")]])
    smooth = build_mesh("Box", v, t)  # no normals: one vertex per position
    assert smooth.vertex_count == 8 and smooth.ranges[0].material == -1


@pytest.mark.parametrize("types", [VertexTypes(),
                                   VertexTypes(*(k[-1] for k in (POSITION_TYPES, NORMAL_TYPES, UV_TYPES)),
                                               "FLOAT_4", "UINT16_4"),
                                   VertexTypes(normal="NORM_2_10_10_10", uv="HALF_2", weight="UNORM16_4")])
def test_rebuilding_from_the_decoded_arrays_gives_identical_bytes(types):
    """What an importer gets from ``mesh_arrays``, exported again, is the same file."""
    rng = np.random.default_rng(3)
    v, t = uv_sphere(rings=6, segments=10)
    normals = rng.normal(size=(len(t), 3, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    uvs = rng.random((len(t), 3, 2)).astype(np.float32)
    uvs[::2] = uvs[1::2]  # shared corners
    weights = rng.random((len(v), 6))[:, :4] * (rng.random((len(v), 4)) > 0.3)
    indices = rng.integers(0, 7, (len(v), 4))
    slots = rng.integers(0, 3, len(t))
    first = build_mesh("S", v, t, corner_normals=normals, corner_uvs=uvs, triangle_slots=slots,
                       slot_materials=[2, 0, 1], weights=weights, bone_indices=indices, skeleton=0, types=types)
    a = mesh_arrays(first)
    again = build_mesh("S", a.positions, a.triangles, corner_normals=a.normals[a.triangles],
                       corner_uvs=a.uvs[a.triangles], triangle_slots=a.triangle_slots,
                       slot_materials=a.slot_materials, weights=a.weights, bone_indices=a.bone_indices,
                       skeleton=0, types=types)
    assert to_bytes(GFGScene(meshes=[again])) == to_bytes(GFGScene(meshes=[first]))


def test_canonical_skin_sums_exactly_and_ignores_input_order():
    w = np.array([[0.25, 0.25, 0.5, 0.0], [1 / 3, 1 / 3, 1 / 3, 0], [0, 0, 0, 0]])
    i = np.array([[7, 3, 1, 9], [5, 2, 8, 4], [1, 2, 3, 4]])
    q, idx = canonical_skin(w, i)
    assert q.dtype == np.uint8 and q.sum(axis=1).tolist() == [255, 255, 0]
    assert idx.tolist() == [[1, 3, 7, 0], [2, 5, 8, 0], [0, 0, 0, 0]]
    perm = [2, 0, 3, 1]
    q2, idx2 = canonical_skin(w[:, perm], i[:, perm])
    assert np.array_equal(q, q2) and np.array_equal(idx, idx2)
    f, _ = canonical_skin(w, i, "FLOAT_4")
    assert f.dtype == np.float32 and np.allclose(f.sum(axis=1), [1, 1, 0], atol=1e-6)


def test_world_matrices_compose_parent_inverse_and_trs():
    parent = Node("P", translation=np.float32([1, 0, 0]), rotation=np.float32([0, 0, np.pi / 2]))
    inverse = np.eye(4, dtype=np.float32)
    inverse[:3, 3] = (0, 0, -1)
    child = Node("C", 0, translation=np.float32([1, 0, 0]), scale=np.float32([2, 2, 2]), parent_inverse=inverse)
    compose_world([parent, child])
    assert np.allclose(child.world @ [0, 0, 0, 1], [1, 1, -1, 1], atol=1e-6)
    assert np.allclose(child.world[:3, :3], euler_xyz_matrix([0, 0, np.pi / 2]) * 2, atol=1e-6)
    r = euler_xyz_matrix([0.3, 0.0, 0.0])
    assert np.allclose(r @ [0, 1, 0], [0, np.cos(0.3), np.sin(0.3)])
    assert mesh_arrays(build_mesh("B", *box())).normals is None
    assert Logic.NAMES[Logic.WEIGHT_INDEX] == "WEIGHT_INDEX"

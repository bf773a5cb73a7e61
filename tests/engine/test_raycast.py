"""Scene triangles in world space, camera rays, exact closest hits and shadow rays."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import box, uv_sphere
from snapshots import SkinData, mesh, snapshot, translation

from voxgi.voxgi_addon.scene.camera import camera_ray_lengths, camera_rays
from voxgi.voxgi_addon.scene.geometry import SceneTriangles, world_triangles
from voxgi.voxgi_addon.scene.raycast import build_grid, closest_hits, occluded, primary_visibility
from voxgi.voxgi_addon.scene.snapshot import ArmatureData, CameraData, ObjectData


def soup(positions):
    """SceneTriangles from (T, 3, 3) corners (materials/objects 0)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3, 3)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    zeros = np.zeros(len(p), np.int32)
    return SceneTriangles(p, n, zeros, zeros)


def brute_force(tris, origins, dirs, t_min=0.0, t_max=np.inf):
    """Reference nearest hit: every ray against every triangle (float64 Möller–Trumbore)."""
    p = tris.positions
    v0, e1, e2 = p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    best_t = np.full(len(origins), np.inf)
    best_tri = np.full(len(origins), -1)
    for i, (o, d) in enumerate(zip(origins, dirs)):
        pv = np.cross(d, e2)
        det = (e1 * pv).sum(1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0
            u = (s * pv).sum(1) * inv
            q = np.cross(s, e1)
            v = (d * q).sum(1) * inv
            t = (e2 * q).sum(1) * inv
        ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > t_min) & (t < t_max)
        if ok.any():
            j = np.flatnonzero(ok)[np.argmin(t[ok])]
            best_t[i], best_tri[i] = t[j], j
    return best_t, best_tri


def random_scene(rng, count):
    """Random triangles: a mix of small scattered ones and a few big ones crossing the scene."""
    centres = rng.uniform(-2, 2, size=(count, 1, 3))
    corners = centres + rng.normal(scale=rng.choice([0.05, 0.3]), size=(count, 3, 3))
    big = rng.uniform(-3, 3, size=(max(1, count // 20), 3, 3))
    return soup(np.concatenate([corners, big]))


def random_rays(rng, count):
    origins = rng.uniform(-4, 4, size=(count, 3))
    dirs = rng.normal(size=(count, 3))
    return origins, dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


# --------------------------------------------------------------------------- known geometry

def test_rays_hit_a_quad_at_known_distances_from_both_sides():
    quad = soup([[(-1, -1, 0), (1, -1, 0), (1, 1, 0)], [(-1, -1, 0), (1, 1, 0), (-1, 1, 0)]])
    origins = np.array([[0.5, -0.5, 5.0], [-0.5, 0.5, 2.0], [0.2, 0.1, -3.0], [2.0, 0.0, 5.0]])
    dirs = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    t, tri, u, v = closest_hits(quad, origins, dirs)
    np.testing.assert_allclose(t[:3], [5.0, 2.0, 3.0])
    assert list(tri) == [0, 1, 0, -1] and t[3] == np.inf
    # barycentrics give back the hit point
    p = quad.positions[tri[0]]
    hit = p[0] + u[0] * (p[1] - p[0]) + v[0] * (p[2] - p[0])
    np.testing.assert_allclose(hit, [0.5, -0.5, 0.0], atol=1e-12)


def test_nearest_face_of_a_box_and_t_bounds():
    positions, triangles = box((2.0, 2.0, 2.0))
    tris = soup(positions[triangles])
    origins = np.array([[-5.0, 0.1, 0.2], [0.0, 0.0, 0.0], [0.3, -0.2, 9.0]])
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    t, tri, _, _ = closest_hits(tris, origins, dirs)
    np.testing.assert_allclose(t, [4.0, 1.0, 8.0])
    t2, _, _, _ = closest_hits(tris, origins, dirs, t_min=[4.5, 0.0, 8.5])  # skip the first face
    np.testing.assert_allclose(t2, [6.0, 1.0, 10.0])
    t3, tri3, _, _ = closest_hits(tris, origins, dirs, t_max=[3.9, 2.0, 7.0])
    assert t3[0] == np.inf and tri3[0] == -1 and t3[1] == 1.0 and t3[2] == np.inf


def test_sphere_hits_match_the_analytic_distance():
    positions, triangles = uv_sphere(rings=40, segments=80, radius=1.0)
    tris = soup(positions[triangles])
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t, tri, _, _ = closest_hits(tris, -3.0 * dirs, dirs)  # aimed at the centre from 3 m
    assert (tri >= 0).all()
    np.testing.assert_allclose(t, 2.0, atol=2e-3)  # tessellation error of a 40×80 sphere


@pytest.mark.parametrize("seed", range(6))
def test_closest_hits_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    tris = random_scene(rng, int(rng.integers(1, 300)))
    origins, dirs = random_rays(rng, 400)
    t, tri, _, _ = closest_hits(tris, origins, dirs)
    ref_t, ref_tri = brute_force(tris, origins, dirs)
    np.testing.assert_array_equal(np.isfinite(t), np.isfinite(ref_t))
    np.testing.assert_allclose(t[np.isfinite(t)], ref_t[np.isfinite(ref_t)], rtol=1e-9)
    same = tri == ref_tri
    # different triangle only where two hits tie (shared edges)
    assert np.allclose(t[~same], ref_t[~same], rtol=1e-9)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), count=st.integers(1, 60), t_max=st.floats(0.1, 10.0))
def test_occluded_agrees_with_closest_hits(seed, count, t_max):
    rng = np.random.default_rng(seed)
    tris = random_scene(rng, count)
    origins, dirs = random_rays(rng, 200)
    eps = 1e-4
    t, _, _, _ = closest_hits(tris, origins, dirs, t_min=eps, t_max=t_max - eps)
    np.testing.assert_array_equal(occluded(tris, origins, dirs, t_max, epsilon=eps), np.isfinite(t))


def test_grid_is_reused_and_empty_scenes_miss():
    tris = soup([[(0, 0, 0), (1, 0, 0), (0, 1, 0)]])
    grid = build_grid(tris)
    o, d = np.array([[0.2, 0.2, 1.0]]), np.array([[0.0, 0.0, -1.0]])
    assert closest_hits(grid, o, d)[1][0] == 0 and closest_hits(tris, o, d)[1][0] == 0
    empty = soup(np.zeros((0, 3, 3)))
    t, tri, _, _ = closest_hits(empty, o, d)
    assert tri[0] == -1 and not occluded(empty, o, d, 10.0)[0]


# --------------------------------------------------------------------------- camera

def perspective_camera(width=8, height=6, lens_angle=math.radians(60), shift=(0.0, 0.0)):
    """A camera at (1, 2, 3) looking down -Z, with a Blender-style (AUTO fit) projection."""
    near, far = 0.1, 100.0
    half = math.tan(lens_angle / 2)  # horizontal half extent at unit depth (width is larger)
    hx, hy = half, half * height / width
    cx, cy = shift[0] * 2 * half, shift[1] * 2 * half
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = 1 / hx, 1 / hy
    p[0, 2], p[1, 2] = cx / hx, cy / hy
    p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1.0
    return CameraData("cam", translation(1, 2, 3), p, (width, height), "PERSP",
                      angle_x=lens_angle, clip_start=near, clip_end=far)


def test_perspective_rays_go_through_pixel_centres_top_row_first():
    cam = perspective_camera(shift=(0.1, -0.05))
    origins, dirs = camera_rays(cam)
    assert origins.shape == dirs.shape == (48, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    # project back through the projection matrix: NDC of pixel (i, j) centre, row 0 on top
    local = np.concatenate([dirs, np.zeros((48, 1))], axis=1)
    clip = local @ cam.projection_matrix.T
    ndc = clip[:, :2] / clip[:, 3:]
    j, i = np.divmod(np.arange(48), 8)
    np.testing.assert_allclose(ndc[:, 0], 2 * (i + 0.5) / 8 - 1, atol=1e-12)
    np.testing.assert_allclose(ndc[:, 1], 1 - 2 * (j + 0.5) / 6, atol=1e-12)
    # origins on the near plane (z = 3 - 0.1), on the ray through the camera position
    np.testing.assert_allclose(origins[:, 2], 2.9)
    back = origins - dirs * (0.1 / -dirs[:, 2:])
    np.testing.assert_allclose(back, np.tile([1.0, 2.0, 3.0], (48, 1)), atol=1e-12)
    lengths = camera_ray_lengths(cam, dirs)
    np.testing.assert_allclose((origins + dirs * lengths[:, None])[:, 2], 3.0 - 100.0)


def test_other_aspect_keeps_the_larger_dimension_field_of_view():
    cam = perspective_camera(8, 6)
    _, wide = camera_rays(cam, 16, 4)  # wider frame: same horizontal field
    _, tall = camera_rays(cam, 3, 6)  # portrait: the vertical side takes the field
    half = math.tan(math.radians(30))
    edge = lambda d: d[:, :2] / -d[:, 2:]  # noqa: E731
    np.testing.assert_allclose(np.abs(edge(wide)[:, 0]).max(), half * 15 / 16)
    np.testing.assert_allclose(np.abs(edge(tall)[:, 1]).max(), half * 5 / 6)


def test_orthographic_rays_are_parallel_and_spaced_by_the_ortho_scale():
    p = np.diag([2 / 4.0, 2 / 2.0, -2 / 9.9, 1.0])  # 4 m × 2 m view
    cam = CameraData("o", translation(0, 0, 3), p, (8, 4), "ORTHO", ortho_scale=4.0,
                     clip_start=1.0, clip_end=10.0)
    origins, dirs = camera_rays(cam)
    np.testing.assert_allclose(dirs, np.tile([0, 0, -1.0], (32, 1)))
    np.testing.assert_allclose(origins[:8, 0], -2 + (np.arange(8) + 0.5) * 0.5)
    np.testing.assert_allclose(origins[::8, 1], 1 - (np.arange(4) + 0.5) * 0.5)
    np.testing.assert_allclose(origins[:, 2], 2.0)
    np.testing.assert_allclose(camera_ray_lengths(cam, dirs), 9.0)


def test_primary_visibility_of_a_floor_and_the_background():
    floor = soup([[(-1, -1, 0), (1, -1, 0), (1, 1, 0)], [(-1, -1, 0), (1, 1, 0), (-1, 1, 0)]])
    floor = SceneTriangles(floor.positions, -floor.normals, np.array([3, 4], np.int32),
                           np.array([0, 0], np.int32))  # normals pointing away from the camera
    p = np.diag([2 / 4.0, 2 / 4.0, -0.2, 1.0])
    cam = CameraData("o", translation(0, 0, 3), p, (8, 8), "ORTHO", clip_start=0.1, clip_end=10.0)
    hits = primary_visibility(floor, cam)
    assert hits.hit.sum() == 16 and hits.hit[2:6, 2:6].all()
    np.testing.assert_allclose(hits.normal[hits.hit], np.tile([0, 0, 1.0], (16, 1)))
    np.testing.assert_allclose(hits.depth[hits.hit], 2.9)
    assert set(hits.material[hits.hit].tolist()) == {3, 4} and (hits.material[~hits.hit] == -1).all()
    assert (hits.position[~hits.hit] == 0).all() and (hits.normal[~hits.hit] == 0).all()


# --------------------------------------------------------------------------- world triangles

def test_world_triangles_place_objects_with_their_matrix():
    tri_mesh = mesh("t", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], material=0)
    rot = translation(5, 0, 0)
    rot[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90° about Z
    snap = snapshot([tri_mesh], [("a", "t", translation(0, 0, 2)), ("b", "t", rot, "rigid")])
    tris = world_triangles(snap)
    np.testing.assert_allclose(tris.positions[0], [(0, 0, 2), (1, 0, 2), (0, 1, 2)])
    np.testing.assert_allclose(tris.positions[1], [(5, 0, 0), (5, 1, 0), (4, 0, 0)])
    np.testing.assert_allclose(tris.normals, [(0, 0, 1), (0, 0, 1)], atol=1e-12)
    assert tris.objects.tolist() == [0, 1] and tris.materials.tolist() == [0, 0]


def test_skinned_vertices_follow_blended_bones():
    # Two bones along +X; bone 1 is posed 90° about Z around its head at (1, 0, 0).
    rest = np.stack([np.eye(4), translation(1, 0, 0)])
    pose1 = translation(1, 0, 0)
    pose1[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    arm = ArmatureData("rig", ("b0", "b1"), np.array([-1, 0], np.int32), rest,
                       np.stack([np.eye(4), pose1]), translation(0, 0, 1))
    weights = np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0.5, 0.5, 0, 0], [0, 0, 0, 0]], np.float32)
    indices = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0]], np.uint8)
    skin = SkinData(weights, indices, "rig")
    strip = mesh("s", [(0.5, 0, 0), (2, 0, 0), (1, 1, 0), (3, 3, 0)], [(0, 1, 2), (1, 3, 2)], skin=skin)
    snap = snapshot([strip], [ObjectData("s", "s", translation(0, 0, 1), "skinned", "rig")])
    snap = type(snap)(snap.meshes, snap.materials, snap.objects, armatures={"rig": arm})
    tris = world_triangles(snap)
    v = {tuple(np.round(c, 9)) for c in tris.positions.reshape(-1, 3)}
    # bone 0 keeps (0.5, 0, 0); bone 1 turns (2, 0, 0) to (1, 1, 0); the half/half vertex
    # (1, 1, 0) goes to the mean of (1, 1, 0) and its bone-1 image (0, 0, 0); unweighted follows
    # the object. Everything is lifted by the object's z = 1.
    assert v == {(0.5, 0, 1), (1, 1, 1), (0.5, 0.5, 1), (3, 3, 1)}


# --------------------------------------------------------------------------- shading normals

from dataclasses import dataclass  # noqa: E402

from voxgi.voxgi_addon.scene.snapshot import MeshData  # noqa: E402


@dataclass(frozen=True)
class MeshWithNormals(MeshData):
    """MeshData with the optional per-corner shading normals world_triangles reads."""

    corner_normals: np.ndarray | None = None


def test_primary_visibility_interpolates_corner_normals():
    positions, triangles = uv_sphere(rings=8, segments=16, radius=1.0)
    corners = (positions / np.linalg.norm(positions, axis=1, keepdims=True))[triangles]
    sphere = MeshWithNormals("s", positions.astype(np.float32), triangles.astype(np.int32),
                             np.zeros(len(triangles), np.int32), corner_normals=corners.astype(np.float32))
    turn = translation(0.2, 0.1, 0.0)
    turn[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    snap = snapshot([sphere], [("s", "s", turn)])
    tris = world_triangles(snap)
    assert tris.corner_normals.shape == (len(triangles), 3, 3)
    p = np.diag([2 / 3.0, 2 / 3.0, -0.2, 1.0])
    cam = CameraData("o", translation(0.2, 0.1, 5), p, (24, 24), "ORTHO", clip_start=0.1, clip_end=20.0)
    hits = primary_visibility(tris, cam)
    exact = hits.position[hits.hit] - [0.2, 0.1, 0.0]
    exact /= np.linalg.norm(exact, axis=1, keepdims=True)
    smooth_error = np.degrees(np.arccos(np.clip((hits.normal[hits.hit] * exact).sum(1), -1, 1)))
    face_error = np.degrees(np.arccos(np.clip((hits.face_normal[hits.hit] * exact).sum(1), -1, 1)))
    assert smooth_error.mean() < 0.3 * face_error.mean()
    assert (hits.normal[hits.hit][:, 2] > 0).all()  # towards the camera


def test_corner_normals_follow_the_object_and_default_to_flat():
    quad = [(0, 0, 0), (1, 0, 0), (1, 1, 0)]
    up = np.tile([0.0, 0.0, 1.0], (1, 3, 1)).astype(np.float32)
    plain = mesh("plain", quad, [(0, 1, 2)])
    tilted = MeshWithNormals("tilted", np.array(quad, np.float32), np.array([(0, 1, 2)], np.int32),
                             np.zeros(1, np.int32), corner_normals=up)
    flip = translation()
    flip[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # +90° about X: +Z → -Y
    snap = snapshot([plain, tilted], [("a", "plain", translation()), ("b", "tilted", flip)])
    tris = world_triangles(snap)
    np.testing.assert_allclose(tris.corner_normals[0], np.tile(tris.normals[0], (3, 1)))  # flat fallback
    np.testing.assert_allclose(tris.corner_normals[1], np.tile([0, -1.0, 0], (3, 1)), atol=1e-12)


def test_a_nan_triangle_leaves_the_bounds_and_the_grid_finite():
    """A triangle with a NaN corner (the voxelizer drops and counts it) must not make the
    scene's bounds NaN, nor the ray grid built over them; rays still hit the good triangle."""
    good = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    bad = np.array([[[np.nan, 0.0, 0.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]]])
    tris = soup(np.concatenate([good, bad]))
    lo, hi = tris.bounds
    np.testing.assert_array_equal(lo, [0, 0, 0])
    np.testing.assert_array_equal(hi, [1, 1, 0])
    grid = build_grid(tris)
    assert np.all(np.isfinite(grid.origin)) and np.all((grid.dims > 0) & (grid.dims < 1000))
    t, tri, _, _ = closest_hits(tris, np.array([[0.2, 0.2, 1.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert tri[0] == 0 and t[0] == pytest.approx(1.0)

"""The view fit's probe rays without a grid (voxgi_addon/scene/raycast.py
``camera_first_hits``): each pixel-centre ray is tested against the triangles whose projected
bounds hold it, and finds what ``primary_visibility`` finds through the grid: the same
distances, points and coverage, holdouts, ray visibility and cut-outs included."""
import dataclasses
import math

import numpy as np
import pytest
from test_cutout_rays import card_and_wall, mask_pixels
from view_scenes import look_at, perspective

from voxgi.voxgi_addon.scene import raycast
from voxgi.voxgi_addon.scene.geometry import SceneTriangles
from voxgi.voxgi_addon.scene.snapshot import RAY_ALL, RAY_CAMERA, TextureData


def soup(seed, count=3000):
    """Small random triangles around the origin (some huge, some reaching behind the camera,
    one with a NaN corner), with random camera visibility and holdouts."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-2.0, 2.0, (count, 1, 3))
    positions = centres + rng.normal(scale=0.15, size=(count, 3, 3))
    positions[:6] = rng.uniform(-30.0, 30.0, (6, 3, 3))  # big ones, across the eye's plane
    positions[6, 1, 0] = np.nan
    e1, e2 = positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0]
    normal = np.cross(e1, e2)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    visibility = np.where(rng.random(count) < 0.1, RAY_ALL & ~RAY_CAMERA, RAY_ALL).astype(np.uint8)
    return SceneTriangles(positions, normal, np.zeros(count, np.int32), np.zeros(count, np.int32),
                          visibility=visibility, holdout=rng.random(count) < 0.05)


def assert_same_as_primary_visibility(tris, camera, width, height):
    assert raycast._projected_pairs(tris, camera, width, height, 10 ** 9) is not None
    depth, position, shows = raycast.camera_first_hits(tris, camera, width, height)
    assert tris not in raycast._GRIDS  # no grid was built
    hits = raycast.primary_visibility(tris, camera, width, height)
    assert np.array_equal(depth, hits.depth.reshape(-1))
    assert np.array_equal(shows, hits.hit.reshape(-1))
    assert np.array_equal(position, hits.position.reshape(-1, 3))
    return shows


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_triangles_seen_through_their_projected_bounds_are_seen_as_the_grid_sees_them(seed):
    tris = soup(seed)
    camera = perspective(look_at((0.3, -5.0, 0.8), (0.0, 0.0, 0.0)), 64, 36)
    shows = assert_same_as_primary_visibility(tris, camera, 64, 36)
    assert 0.2 < shows.mean() < 1.0  # something seen, something held out or missed
    depth, _, _ = raycast.camera_first_hits(tris, camera, 64, 36)
    assert (np.isfinite(depth) & ~shows).any()  # the holdouts stop rays and show nothing


def test_an_orthographic_camera_and_a_camera_inside_the_triangles(monkeypatch):
    monkeypatch.setattr(raycast, "PROJECTED_PAIRS_PER_RAY", 10 ** 6)  # the pairs, however many
    tris = soup(3)
    ortho = perspective(look_at((0.0, -6.0, 0.5), (0.0, 0.0, 0.0)), 48, 32)
    p = np.asarray(ortho.projection_matrix).copy()
    p[0, 0], p[1, 1], p[2, 2], p[2, 3], p[3, 2], p[3, 3] = 1 / 3, 1 / 2, -2 / 999.99, -1.0, 0, 1
    ortho = dataclasses.replace(ortho, type="ORTHO", projection_matrix=p)
    assert_same_as_primary_visibility(tris, ortho, 48, 32)
    inside = perspective(look_at((0.0, 0.0, 0.0), (1.0, 0.2, 0.1)), 40, 30, fov=math.radians(90))
    assert_same_as_primary_visibility(soup(5), inside, 40, 30)


def test_cut_outs_let_the_probe_rays_through_per_texel():
    texture = TextureData("mask", mask_pixels(), interpolation="Closest", extension="REPEAT",
                          key="mask")
    tris = card_and_wall(alpha_texture=0, textures=(texture,))
    camera = perspective(look_at((1.0, 1.0, 4.0), (1.0, 1.0, 0.0), up=(0.0, 1.0, 0.0)), 48, 48,
                         fov=math.radians(40))
    shows = assert_same_as_primary_visibility(tris, camera, 48, 48)
    _, position, _ = raycast.camera_first_hits(tris, camera, 48, 48)
    card, wall = np.isclose(position[:, 2], 1.0), np.isclose(position[:, 2], 0.0)
    assert shows.all() and card.mean() > 0.2 and wall.mean() > 0.2  # half the card cut away


def test_triangles_that_would_pair_with_too_many_rays_are_traced_through_a_grid(monkeypatch):
    tris = soup(4, count=400)
    camera = perspective(look_at((0.3, -5.0, 0.8), (0.0, 0.0, 0.0)), 64, 36)
    assert raycast._projected_pairs(tris, camera, 64, 36, 100) is None
    monkeypatch.setattr(raycast, "PROJECTED_PAIRS_PER_RAY", 0)
    depth, _, shows = raycast.camera_first_hits(tris, camera, 64, 36)
    assert tris in raycast._GRIDS
    hits = raycast.primary_visibility(tris, camera, 64, 36)
    assert np.array_equal(depth, hits.depth.reshape(-1)) and shows.any()

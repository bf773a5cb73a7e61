"""preview.film: the world behind the geometry and the alpha (no bpy)."""
from __future__ import annotations

import numpy as np
import pytest

from voxgi.voxgi_addon.preview.film import background, film_combined
from voxgi.voxgi_addon.scene.snapshot import CameraData, WorldData


def test_opaque_film_fills_the_uncovered_share_with_the_background():
    combined = np.full((2, 3, 3), 0.5, np.float32)
    alpha = np.array([[1.0, 0.25, 0.0], [0.0, 0.0, 1.0]], np.float32)
    back = np.full((2, 3, 3), 2.0, np.float32)
    rgba = film_combined(combined, alpha, back, transparent=False)
    assert rgba.shape == (2, 3, 4)
    assert np.allclose(rgba[..., 0], 0.5 + (1.0 - alpha) * 2.0)
    assert np.all(rgba[..., 3] == 1.0)


def test_transparent_film_keeps_the_traced_light_and_the_coverage_as_alpha():
    combined = np.full((2, 3, 3), 0.5, np.float32)
    alpha = np.array([[1.0, 0.25, 0.0], [0.0, 0.0, 1.0]], np.float32)
    rgba = film_combined(combined, alpha, None, transparent=True)
    assert np.array_equal(rgba[..., :3], combined) and np.array_equal(rgba[..., 3], alpha)


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match="Alpha"):
        film_combined(np.zeros((2, 3, 3)), np.zeros((3, 2)), np.zeros((2, 3, 3)), False)


def test_a_sky_map_is_seen_up_and_the_ground_down_and_a_black_world_is_black():
    from voxgi.voxgi_addon.scene.equirect import pixel_directions

    dirs = pixel_directions(32, 64)  # a map bright above the horizon, dark below
    radiance = (np.where(dirs[..., 2:3] > 0.0, 3.0, 0.5) * np.ones((1, 1, 3))).astype(np.float32)
    world = WorldData(radiance=radiance, strength=1.0, key="film-test")
    # a level camera at the origin looking along +Y (local -Z → world +Y, local Y → world Z)
    matrix = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], np.float64)
    camera = CameraData(name="Camera", world_matrix=matrix, projection_matrix=np.eye(4),
                        resolution=(16, 12), angle_x=0.8, angle_y=0.6)
    back = background(world, camera, 16, 12)
    assert back.shape == (12, 16, 3) and back.dtype == np.float32
    assert np.allclose(back[0], 3.0, atol=1e-4)   # the top row sees the bright sky
    assert np.allclose(back[-1], 0.5, atol=1e-4)  # the bottom row the dark ground
    assert np.all(background(WorldData(), camera, 16, 12) == 0.0)
    with pytest.raises(ValueError, match="size"):
        background(world, camera, 0, 12)


def test_a_holdout_shows_neither_surface_nor_world():
    combined = np.zeros((1, 3, 3), np.float32)
    alpha = np.array([[0.0, 0.5, 0.0]], np.float32)
    holdout = np.array([[1.0, 0.5, 0.25]], np.float32)
    back = np.full((1, 3, 3), 2.0, np.float32)
    opaque = film_combined(combined, alpha, back, False, holdout)
    assert np.allclose(opaque[0, :, 3], [0.0, 0.5, 0.75])
    assert np.allclose(opaque[0, :, 0], [0.0, 0.0, 1.5])
    transparent = film_combined(combined, alpha, back, True, holdout)
    assert np.allclose(transparent[0, :, 3], alpha[0])

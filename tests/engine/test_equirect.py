"""The equirect map convention (voxgi_addon/scene/equirect.py)."""
import numpy as np
import pytest

from voxgi.voxgi_addon.scene import equirect


def test_pixel_centres_follow_the_convention():
    dirs = equirect.pixel_directions(4, 8)
    assert dirs.shape == (4, 8, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    # row 0 is the zenith side, the last row the nadir side
    assert np.all(dirs[0, :, 2] > 0.9 * np.sin(np.pi / 2 - 0.5 * np.pi / 4))
    assert np.all(dirs[-1, :, 2] < 0)
    # column centres: phi = -pi + (j + 0.5) * 2 pi / W, phi = atan2(y, x)
    phi = np.arctan2(dirs[1, :, 1], dirs[1, :, 0])
    np.testing.assert_allclose(phi, -np.pi + (np.arange(8) + 0.5) * 2 * np.pi / 8, atol=1e-12)
    el = np.arcsin(dirs[:, 0, 2])
    np.testing.assert_allclose(el, np.pi / 2 - (np.arange(4) + 0.5) * np.pi / 4, atol=1e-12)
    # +X is at the middle of the map (between columns W/2 - 1 and W/2), +Y three quarters in
    rows, cols = equirect.direction_to_pixel(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), 4, 8)
    np.testing.assert_allclose(cols[:2], [4.0, 6.0], atol=1e-12)
    np.testing.assert_allclose(rows, [2.0, 2.0, 0.0], atol=1e-12)


def test_direction_pixel_round_trip():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    rows, cols = equirect.direction_to_pixel(d, 64, 128)
    assert np.all((rows >= 0) & (rows <= 64) & (cols >= 0) & (cols <= 128))
    np.testing.assert_allclose(equirect.pixel_to_direction(rows, cols, 64, 128), d, atol=1e-9)
    # pixel centres come back at integer + 0.5
    grid = equirect.pixel_directions(16, 32)
    rows, cols = equirect.direction_to_pixel(grid, 16, 32)
    np.testing.assert_allclose(rows, (np.arange(16) + 0.5)[:, None] * np.ones((1, 32)), atol=1e-9)
    np.testing.assert_allclose(cols, (np.arange(32) + 0.5)[None, :] * np.ones((16, 1)), atol=1e-9)
    # the direction's length does not matter
    r2, c2 = equirect.direction_to_pixel(grid * 3.5, 16, 32)
    np.testing.assert_allclose((r2, c2), (rows, cols), atol=1e-9)


def test_bilinear_sampling_hits_pixel_centres_and_wraps():
    rng = np.random.default_rng(5)
    image = rng.random((8, 16, 3)).astype(np.float32)
    np.testing.assert_allclose(equirect.sample_bilinear(image, equirect.pixel_directions(8, 16)),
                               image, atol=1e-5)
    # halfway between the last and the first column (phi = +-pi) is their mean
    d = equirect.pixel_to_direction(np.array([2.5]), np.array([0.0]), 8, 16)
    np.testing.assert_allclose(equirect.sample_bilinear(image, d)[0],
                               0.5 * (image[2, 0] + image[2, 15]), atol=1e-5)
    d = equirect.pixel_to_direction(np.array([2.5]), np.array([16.0]), 8, 16)
    np.testing.assert_allclose(equirect.sample_bilinear(image, d)[0],
                               0.5 * (image[2, 0] + image[2, 15]), atol=1e-5)
    # a linear ramp in columns is reproduced between centres
    ramp = np.broadcast_to(np.arange(16, dtype=np.float32)[None, :, None], (8, 16, 1))
    d = equirect.pixel_to_direction(np.full(5, 3.5), np.array([1.5, 2.0, 2.25, 7.9, 14.5]), 8, 16)
    np.testing.assert_allclose(equirect.sample_bilinear(ramp, d)[:, 0], [1.0, 1.5, 1.75, 7.4, 14.0], atol=1e-5)


def test_solid_angles_and_mean():
    w = equirect.row_solid_angles(32, 64)
    assert w.sum() * 64 == pytest.approx(4 * np.pi)
    assert w[0] < w[15] and w[0] == pytest.approx(w[-1])
    const = np.full((32, 64, 3), (0.5, 1.0, 2.0), np.float32)
    np.testing.assert_allclose(equirect.mean_radiance(const), (0.5, 1.0, 2.0), rtol=1e-6)
    # the mean of z over the sphere is 0, of z^2 is 1/3 (a fine map gets both closely)
    dirs = equirect.pixel_directions(256, 512)
    assert equirect.mean_radiance(dirs[..., 2:3])[0] == pytest.approx(0.0, abs=1e-6)
    assert equirect.mean_radiance(dirs[..., 2:3] ** 2)[0] == pytest.approx(1 / 3, rel=1e-4)


def test_box_downsample_keeps_the_mean():
    rng = np.random.default_rng(7)
    image = rng.random((100, 200, 3)).astype(np.float32)
    small = equirect.box_downsample(image, 32)
    assert small.shape == (25, 50, 3)
    np.testing.assert_allclose(small[0, 0], image[:4, :4].mean(axis=(0, 1)), rtol=1e-5)
    np.testing.assert_array_equal(equirect.box_downsample(image, 100), image)
    # sizes that do not divide: rows padded by the last row, columns by wrapping
    odd = equirect.box_downsample(image[:99, :198], 50)
    assert odd.shape == (50, 99, 3)
    np.testing.assert_allclose(odd[-1, -1], image[98:99, 196:198].mean(axis=(0, 1)), rtol=1e-5)

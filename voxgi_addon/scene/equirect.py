"""The equirect (latitude-longitude) map convention of ``WorldData.radiance``.

This module is the only place the convention lives; everything that builds or reads a world map
goes through it. World space, Blender's Z up:

* a map is (H, W, 3) float32 with W = 2H;
* row i has its pixel centre at elevation ``el = pi/2 - (i + 0.5) * pi / H`` (row 0 is the top,
  the zenith side);
* column j has its pixel centre at azimuth ``phi = -pi + (j + 0.5) * 2 pi / W``, where
  ``phi = atan2(y, x)``;
* the direction of (el, phi) is ``(cos el cos phi, cos el sin phi, sin el)``.

Continuous pixel coordinates put pixel centres at integer + 0.5: the pixel (i, j) covers
rows [i, i + 1) and columns [j, j + 1). Pure numpy.
"""
from __future__ import annotations

import numpy as np

from .short_axis import norm3


def pixel_directions(height: int, width: int) -> np.ndarray:
    """(H, W, 3) float64 unit directions of the pixel centres."""
    el = np.pi / 2 - (np.arange(height) + 0.5) * np.pi / height
    phi = -np.pi + (np.arange(width) + 0.5) * 2 * np.pi / width
    cos_el = np.cos(el)[:, None]
    out = np.empty((height, width, 3), np.float64)
    out[..., 0] = cos_el * np.cos(phi)[None, :]
    out[..., 1] = cos_el * np.sin(phi)[None, :]
    out[..., 2] = np.sin(el)[:, None]
    return out


def direction_to_pixel(directions, height: int = 1, width: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (rows, cols) of directions (..., 3), not necessarily unit length.

    With the default size (1, 2) the coordinates are fractions of the map: rows in [0, 1]
    (0 = zenith), cols in [0, 2]; pass the map's height and width for pixel coordinates
    (pixel centres at integer + 0.5). A zero direction maps to the horizon at phi = 0.
    """
    d = np.asarray(directions, np.float64)
    length = norm3(d)
    z = np.divide(d[..., 2], length, out=np.zeros_like(length), where=length > 0)
    el = np.arcsin(np.clip(z, -1.0, 1.0))
    phi = np.arctan2(d[..., 1], d[..., 0])
    rows = (np.pi / 2 - el) * (height / np.pi)
    cols = (phi + np.pi) * (width / (2 * np.pi))
    return rows, cols


def pixel_to_direction(rows, cols, height: int, width: int) -> np.ndarray:
    """Unit directions (..., 3) of continuous pixel coordinates (the inverse of
    ``direction_to_pixel``)."""
    el = np.pi / 2 - np.asarray(rows, np.float64) * (np.pi / height)
    phi = -np.pi + np.asarray(cols, np.float64) * (2 * np.pi / width)
    cos_el = np.cos(el)
    return np.stack([cos_el * np.cos(phi), cos_el * np.sin(phi), np.sin(el)], axis=-1)


def sample_bilinear(image: np.ndarray, directions) -> np.ndarray:
    """Bilinear lookup of an (H, W, C) map in directions (..., 3): (..., C) float32.

    Columns wrap around (phi = -pi meets phi = pi); rows clamp at the poles.
    """
    image = np.asarray(image)
    height, width = image.shape[:2]
    rows, cols = direction_to_pixel(directions, height, width)
    y = np.clip(rows - 0.5, 0.0, height - 1.0)
    x = cols - 0.5
    y0 = np.minimum(np.floor(y).astype(np.int64), height - 1)
    y1 = np.minimum(y0 + 1, height - 1)
    x0f = np.floor(x)
    fy = (y - y0)[..., None]
    fx = (x - x0f)[..., None]
    x0 = x0f.astype(np.int64) % width
    x1 = (x0 + 1) % width
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def row_solid_angles(height: int, width: int) -> np.ndarray:
    """(H,) float64 solid angle (steradians) of one pixel of each row; W * sum = 4 pi."""
    edges = np.pi / 2 - np.arange(height + 1) * np.pi / height
    return (np.sin(edges[:-1]) - np.sin(edges[1:])) * (2 * np.pi / width)


def mean_radiance(image: np.ndarray) -> np.ndarray:
    """(C,) float32 solid-angle-weighted mean of an (H, W, C) map over the sphere."""
    image = np.asarray(image, np.float64)
    height, width = image.shape[:2]
    weights = row_solid_angles(height, width)
    return (np.einsum("i,ijc->c", weights, image) / (4 * np.pi)).astype(np.float32)


def box_downsample(image: np.ndarray, max_height: int) -> np.ndarray:
    """An (H, W, C) map averaged over k x k pixel boxes, k the smallest power of two that
    brings H to at most ``max_height``. Sizes that k does not divide are padded first: rows
    by repeating the last row, columns by wrapping around."""
    image = np.asarray(image, np.float32)
    height, width = image.shape[:2]
    factor = 1
    while height > max_height * factor:
        factor *= 2
    if factor == 1:
        return image
    pad_h = (-height) % factor
    pad_w = (-width) % factor
    if pad_h:
        image = np.concatenate([image, np.repeat(image[-1:], pad_h, axis=0)], axis=0)
    if pad_w:
        image = np.concatenate([image, image[:, :pad_w]], axis=1)
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(h, factor, w, factor, -1).mean(axis=(1, 3), dtype=np.float64).astype(np.float32)


def resample(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """An (H, W, C) map resampled bilinearly (in direction) to (height, width, C)."""
    return sample_bilinear(image, pixel_directions(height, width))

"""Cone-traced terms (diffuse indirect, AO, glossy) traced at a fraction of the pixels, then
upsampled.

Diffuse indirect light is smooth across a surface (on the demo scene, blurring Cycles' own
Diffuse Indirect over 4 pixels changes it by 2%), so the preview can trace its cones at one
pixel of every ``stride`` × ``stride`` block (glossy too: a faster, blurrier reflection) and fill
the others with a joint bilateral upsample that only mixes samples lying on the same surface:
bilinear weights times a normal term max(n·n_k, 0)^8 times a plane term exp(−(|n·(p_k − p)| / (0.1·|p_k − p| + 1e-4))²).
A pixel whose neighbours all fail those tests takes the nearest traced sample within two
blocks. Both tracers (numpy and GPU) use ``sample_pixels`` and ``upsample``, so they agree.
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import norm3

STRIDES = (1, 2, 3, 4)
NORMAL_POWER = 8
PLANE_TOLERANCE = 0.1


AUTO_POINTS = 240 * 180  # most traced points the Auto GI resolution allows


# The emitters' field (``EmitterField``) is evaluated at one point per FIELD_STRIDE ×
# FIELD_STRIDE block at least, whatever the gathers' stride: their per-triangle sums at every
# pixel of a 160 × 120 image were 12% of the emissive room's preview, and the field is smooth
# where it is read (elsewhere the kernels evaluate the sums themselves)
FIELD_STRIDE = 2


def field_stride(gi_stride: int) -> int:
    """The emitters' field's stride for gathers at ``gi_stride`` (``FIELD_STRIDE`` at least)."""
    return max(int(gi_stride), FIELD_STRIDE)


def auto_stride(width: int, height: int) -> int:
    """The smallest stride of STRIDES that traces at most AUTO_POINTS pixels (Quarter beyond)."""
    for stride in STRIDES:
        hl, wl = low_shape(height, width, stride)
        if hl * wl <= AUTO_POINTS:
            return stride
    return STRIDES[-1]


def low_shape(height: int, width: int, stride: int) -> tuple[int, int]:
    return -(-height // stride), -(-width // stride)


def sample_pixels(height: int, width: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows (Hl,), cols (Wl,)) of the full-resolution pixels traced for each low-res cell
    (row 0 = top): the centre of each stride × stride block, clamped to the image."""
    hl, wl = low_shape(height, width, stride)
    rows = np.minimum(np.arange(hl) * stride + stride // 2, height - 1)
    cols = np.minimum(np.arange(wl) * stride + stride // 2, width - 1)
    return rows, cols


def upsample(values: np.ndarray, valid: np.ndarray, hit: np.ndarray, position: np.ndarray,
             normal: np.ndarray, stride: int) -> np.ndarray:
    """Full-resolution (H, W, C) float32 from low-res ``values`` (Hl, Wl, C).

    valid : (Hl, Wl) bool, the low-res cells whose pixel hit a surface; hit : (H, W) bool;
    position, normal : (H, W, 3) the G-buffer (row 0 = top). Background pixels get 0.
    """
    height, width = hit.shape
    if stride == 1:
        return np.where(hit[..., None], values, 0.0).astype(np.float32)
    rows, cols = sample_pixels(height, width, stride)
    hl, wl = len(rows), len(cols)
    ys, xs = np.nonzero(hit)
    p = position[ys, xs].astype(np.float32)
    n = normal[ys, xs].astype(np.float32)
    # The traced cells' G-buffer, flat: cell k = j·Wl + i.
    cell_p = position[rows][:, cols].reshape(-1, 3).astype(np.float32)
    cell_n = normal[rows][:, cols].reshape(-1, 3).astype(np.float32)
    cell_v = values.reshape(-1, values.shape[2]).astype(np.float32)
    cell_ok = valid.reshape(-1).astype(np.float32)
    u = (xs - stride // 2) / stride
    v = (ys - stride // 2) / stride
    i0 = np.clip(np.floor(u).astype(np.int64), 0, wl - 1)
    j0 = np.clip(np.floor(v).astype(np.int64), 0, hl - 1)
    # Quadratic B-spline weights over the 3 × 3 cells around the nearest one (c, t = u − c).
    ci, cj = np.floor(u + 0.5).astype(np.int64), np.floor(v + 0.5).astype(np.int64)
    wu, wv = _bspline(u - ci), _bspline(v - cj)
    total = np.zeros((len(ys), values.shape[2]), np.float32)
    weight = np.zeros(len(ys), np.float32)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            k = np.clip(cj + dj, 0, hl - 1) * wl + np.clip(ci + di, 0, wl - 1)
            w = wu[di + 1] * wv[dj + 1] * cell_ok[k]
            offset = cell_p[k] - p
            facing = np.maximum(np.einsum("ij,ij->i", n, cell_n[k]), 0.0)
            plane = np.abs(np.einsum("ij,ij->i", n, offset))
            scale = PLANE_TOLERANCE * np.sqrt(np.einsum("ij,ij->i", offset, offset)) + 1e-4
            w *= facing ** NORMAL_POWER * np.exp(-(plane / scale) ** 2)
            total += w[:, None] * cell_v[k]
            weight += w
    out = total / np.maximum(weight, 1e-30)[:, None]
    lonely = np.flatnonzero(weight <= 1e-8)
    if len(lonely):
        out[lonely] = _nearest_valid(values, valid, j0[lonely], i0[lonely])
    image = np.zeros((height, width, values.shape[2]), np.float32)
    image[ys, xs] = out
    return image


def _bspline(t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadratic B-spline weights (float32) of cells −1, 0, +1 for offsets t ∈ [−½, ½] from
    the nearest cell: (½ − t)²/2, ¾ − t², (½ + t)²/2."""
    t = np.asarray(t, np.float32)
    return 0.5 * (0.5 - t) ** 2, 0.75 - t * t, 0.5 * (0.5 + t) ** 2


def _nearest_valid(values, valid, j0, i0, reach: int = 2) -> np.ndarray:
    """Value of the nearest valid low-res cell within ``reach`` cells of (j0, i0) (0 if none)."""
    hl, wl = valid.shape
    best = np.full(len(j0), np.inf)
    out = np.zeros((len(j0), values.shape[2]))
    for dj in range(-reach, reach + 2):
        for di in range(-reach, reach + 2):
            j = np.clip(j0 + dj, 0, hl - 1)
            i = np.clip(i0 + di, 0, wl - 1)
            d = (dj - 0.5) ** 2 + (di - 0.5) ** 2
            better = valid[j, i] & (d < best)
            out[better] = values[j[better], i[better]]
            best[better] = d
    return out


class EmitterField:
    """The emitters' unshadowed light at the gather points, read anywhere on the image (the
    numpy twin of ``shaders/upsample.glsl`` UPSAMPLE_FIELD and UPSAMPLE_LIST; docs/gi_pipeline.md
    "Where a preview's time goes"): the emissive triangles' per-triangle sums are evaluated at
    one point per stride × stride block and brought to a pixel's or a sub-pixel sample's point
    with ``upsample``'s weights, together with how far the light's direction turns across the
    taps that bring it (``gi.emitters.NEAR_STEP`` says where that is too far).

    glossy, diffuse : (Hl, Wl, 3) the unshadowed glossy light over the Glossy Color
    (``exact_glossy.emitters_glossy_field``) and Diffuse Direct (``emitters.unshadowed_sum``)
    at the gather points; distance : (Hl, Wl) their distance to the nearest emissive triangle
    that can light them (``emitters.emitter_distances``); valid : (Hl, Wl) bool their pixel
    sees a surface; position, normal : (H, W, 3) the pixel centres' G-buffer (row 0 on top);
    eye : (3,) the camera's position, None for an orthographic camera."""

    def __init__(self, glossy, diffuse, distance, valid, position, normal, stride: int, eye):
        self.glossy = np.asarray(glossy, np.float32)
        self.diffuse = np.asarray(diffuse, np.float32)
        self.distance = np.asarray(distance, np.float32)
        self.valid = np.asarray(valid, bool)
        self.position, self.normal = position, normal
        self.stride = stride
        self.eye = None if eye is None else np.asarray(eye, np.float32)

    def at_centres(self, pixels):
        """``at`` the centres of ``pixels`` (N,) (flat indices, row 0 on top, seeing a
        surface); at stride 1 their own gather points' values, turn 0."""
        height, width = self.position.shape[:2]
        rows, cols = np.divmod(np.asarray(pixels), width)
        if self.stride == 1:
            zero = np.zeros(len(rows), np.float32)
            return (self.glossy[rows, cols], zero, self.diffuse[rows, cols], zero)
        return self.at(rows, cols, self.position[rows, cols], self.normal[rows, cols])

    def at(self, rows, cols, points, normals, offset=(0.0, 0.0)):
        """(glossy (N, 3), its turn (N,), diffuse (N, 3), its turn (N,)) at surface points
        (N, 3) with unit normals, seen through pixels (rows from the top, cols) moved by
        ``offset`` (x right, y down, pixels; a sub-pixel pass's). The turn is the root mean
        square over the taps, by their weights, of the step to the tap over the distance left
        to the emitters beyond it (the distance is 1-Lipschitz) + |n − n_k|; the glossy one
        adds the view direction's turn (step / the camera's distance) and |n − n_k| again; −1
        where no tap weighs (the light 0 there)."""
        p = np.asarray(points, np.float32).reshape(-1, 3)
        n = np.asarray(normals, np.float32).reshape(-1, 3)
        glossy = np.zeros((len(p), 3), np.float32)
        diffuse = np.zeros((len(p), 3), np.float32)
        weight = np.zeros(len(p), np.float32)
        turn2 = np.zeros(len(p), np.float32)
        glossy_turn2 = np.zeros(len(p), np.float32)
        eye_distance = None if self.eye is None else \
            np.maximum(norm3(p - self.eye), np.float32(1e-6))
        for j, i, w, step, nk in _taps(self.valid, self.position, self.normal, self.stride,
                                       rows, cols, p, n, offset):
            glossy += w[:, None] * self.glossy[j, i]
            diffuse += w[:, None] * self.diffuse[j, i]
            weight += w
            room = self.distance[j, i] - step
            bend = norm3(n - nk)
            turn = np.where(room > 0.0, np.minimum(step / np.where(room > 0.0, room, 1.0),
                                                   np.float32(1e15)), np.float32(1e15)) + bend
            turn2 += np.where(w > 0.0, w * turn * turn, 0.0)
            if eye_distance is not None:
                turn = turn + step / eye_distance
            turn = turn + bend
            glossy_turn2 += np.where(w > 0.0, w * turn * turn, 0.0)
        lonely = weight <= 1e-8
        safe = np.where(lonely, 1.0, weight)
        glossy = np.where(lonely[:, None], 0.0, glossy / safe[:, None])
        diffuse = np.where(lonely[:, None], 0.0, diffuse / safe[:, None])
        return (glossy, np.where(lonely, -1.0, np.sqrt(glossy_turn2 / safe)),
                diffuse, np.where(lonely, -1.0, np.sqrt(turn2 / safe)))


def upsample_at(values, valid, position, normal, stride: int, rows, cols, points, normals,
                offset=(0.0, 0.0)):
    """``upsample``'s joint-bilateral weights at any surface points (the numpy twin of
    ``shaders/upsample.glsl`` UPSAMPLE_TERMS; docs/gi_pipeline.md "Anti-aliasing"): a
    sub-pixel pass's samples that see another surface than their pixel's centre read the
    gathers there. values : a sequence of (Hl, Wl, C) low-resolution images of the gather
    points (``gather.gather_gi(low=True)``'s), valid : (Hl, Wl) bool; position, normal :
    (H, W, 3) the pixel centres' G-buffer (the taps'; row 0 on top); points, normals : (N, 3)
    seen through pixels (rows from the top, cols) moved by ``offset`` (x right, y down,
    pixels). Returns ([(N, C) float32 per image], fits (N,) bool): where no tap weighs the
    values are 0 and fits False (the caller keeps the centre's there)."""
    p = np.asarray(points, np.float32).reshape(-1, 3)
    n = np.asarray(normals, np.float32).reshape(-1, 3)
    totals = [np.zeros((len(p), image.shape[-1]), np.float32) for image in values]
    weight = np.zeros(len(p), np.float32)
    for j, i, w, _, _ in _taps(valid, position, normal, stride, rows, cols, p, n, offset):
        for total, image in zip(totals, values):
            total += w[:, None] * image[j, i]
        weight += w
    fits = weight > 1e-8
    safe = np.where(fits, weight, 1.0)[:, None]
    return [np.where(fits[:, None], total / safe, 0.0).astype(np.float32)
            for total in totals], fits


def _taps(valid, position, normal, stride: int, rows, cols, p, n, offset):
    """``upsample``'s 3 × 3 taps around points p (N, 3) float32 with normals n seen through
    pixels (rows, cols) moved by ``offset``: per tap (row j, column i of the gather points,
    weight (N,) float32, the distance to its point (N,), its normal (N, 3))."""
    height, width = position.shape[:2]
    tap_rows, tap_cols = sample_pixels(height, width, stride)
    hl, wl = len(tap_rows), len(tap_cols)
    u = ((np.asarray(cols) + np.float32(offset[0]) - stride // 2) / stride).astype(np.float32)
    v = ((np.asarray(rows) + np.float32(offset[1]) - stride // 2) / stride).astype(np.float32)
    ci, cj = np.floor(u + 0.5).astype(np.int64), np.floor(v + 0.5).astype(np.int64)
    wu, wv = _bspline(u - ci), _bspline(v - cj)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            j, i = np.clip(cj + dj, 0, hl - 1), np.clip(ci + di, 0, wl - 1)
            pk = position[tap_rows[j], tap_cols[i]].astype(np.float32)
            nk = normal[tap_rows[j], tap_cols[i]].astype(np.float32)
            offset_k = pk - p
            facing = np.maximum(np.einsum("ij,ij->i", n, nk), 0.0)
            plane = np.abs(np.einsum("ij,ij->i", n, offset_k))
            step = np.sqrt(np.einsum("ij,ij->i", offset_k, offset_k))
            scale = PLANE_TOLERANCE * step + np.float32(1e-4)
            w = (wu[di + 1] * wv[dj + 1] * valid[j, i] * facing ** NORMAL_POWER
                 * np.exp(-(plane / scale) ** 2)).astype(np.float32)
            yield j, i, w, step, nk


def same_surface(hit_a, material_a, position_a, normal_a, hit_b, material_b, position_b,
                 normal_b) -> np.ndarray:
    """(…) bool: whether two G-buffer samples (hit (…) bool, material (…) int, position,
    normal (…, 3)) see one surface: both see nothing, or both see the same material with
    either point on the other's tangent plane within ``upsample.PLANE_TOLERANCE`` × their
    distance (the joint-bilateral upsample's test; depth steps and creases are not).
    ``passes.edge_pixels`` tests neighbouring pixel centres with it; the sub-pixel passes a
    pass's sample against its pixel's centre (the emitters' glossy light and unshadowed sum,
    ``passes.render_passes``) and against the centres around it (``resolve.resolve_samples``);
    the GLSL port is render/shaders/same_surface.glsl."""
    hit_a, hit_b = np.asarray(hit_a, bool), np.asarray(hit_b, bool)
    step = np.asarray(position_b, np.float64) - np.asarray(position_a, np.float64)
    off_plane = np.maximum(np.abs(np.einsum("...i,...i->...", normal_a, step)),
                           np.abs(np.einsum("...i,...i->...", normal_b, step)))
    apart = off_plane > PLANE_TOLERANCE * norm3(step)
    differ = (hit_a != hit_b) | (hit_a & hit_b & ((np.asarray(material_a) !=
                                                   np.asarray(material_b)) | apart))
    return ~differ

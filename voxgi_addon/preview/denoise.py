"""Edge-aware à-trous filtering of a noisy per-pixel estimate (numpy reference of
``render/shaders/denoise.glsl``).

The ray-traced gather gives each traced pixel a Monte Carlo mean and the variance of that mean.
The spatial part of SVGF (Schied et al. 2017) removes the remaining noise without blurring what
is real: ``iterations`` passes of a 5 × 5 B3-spline kernel whose taps are 2^i pixels apart, each
tap weighted by

* geometry: same surface only — normal term max(n·n_q, 0)^NORMAL_POWER times the plane term
  exp(−(|n·(p_q − p)| / (PLANE_TOLERANCE·|p_q − p| + 1e-4))²) (as ``upsample``);
* luminance: exp(−|l_p − l_q| / (SIGMA_LUMINANCE·√var_p + ε)), so differences larger than the
  noise (contact shadows, light gradients) survive while differences of the noise's size are
  averaged away.

Variance is filtered with the squared weights (the variance of the weighted mean), so later
passes trust the already smoothed values more. Pixels that see no surface take no part.
Deterministic: no randomness, fixed order of taps.
"""
from __future__ import annotations

import numpy as np

KERNEL = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
NORMAL_POWER = 32
PLANE_TOLERANCE = 0.1
SIGMA_LUMINANCE = 4.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
_EPSILON = 1e-6


def _shifted(image: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """image[y + dy, x + dx] with ``fill`` outside (same shape as ``image``)."""
    out = np.full_like(image, fill)
    h, w = image.shape[:2]
    ys = slice(max(0, -dy), min(h, h - dy))
    xs = slice(max(0, -dx), min(w, w - dx))
    ys_src = slice(max(0, dy), min(h, h + dy))
    xs_src = slice(max(0, dx), min(w, w + dx))
    out[ys, xs] = image[ys_src, xs_src]
    return out


def atrous_filter(values: np.ndarray, variance: np.ndarray, valid: np.ndarray,
                  position: np.ndarray, normal: np.ndarray, iterations: int = 4,
                  sigma_luminance: float = SIGMA_LUMINANCE) -> tuple[np.ndarray, np.ndarray]:
    """Filter ``values`` along surfaces.

    Parameters
    ----------
    values : (H, W, C) float, the per-pixel means (C ≥ 3; luminance from the first three).
    variance : (H, W) float ≥ 0, the variance of each mean's luminance.
    valid : (H, W) bool, pixels that see a surface (others are left as they are).
    position, normal : (H, W, 3) world-space G-buffer of those pixels (metres, unit normals).
    iterations : passes with tap spacing 1, 2, 4, …

    Returns
    -------
    (values, variance) filtered, float32, same shapes.
    """
    v = np.asarray(values, np.float64).copy()
    var = np.asarray(variance, np.float64).copy()
    ok = np.asarray(valid, bool)
    p = np.asarray(position, np.float64)
    n = np.asarray(normal, np.float64)
    for it in range(iterations):
        step = 1 << it
        lum = v[..., :3] @ LUMINANCE
        scale = sigma_luminance * np.sqrt(np.maximum(var, 0.0)) + _EPSILON
        total = np.zeros_like(v)
        total_var = np.zeros_like(var)
        weight = np.zeros(var.shape)
        for a, ky in enumerate(KERNEL):
            for b, kx in enumerate(KERNEL):
                dy, dx = (a - 2) * step, (b - 2) * step
                q_ok = _shifted(ok, dy, dx, False)
                q_p = _shifted(p, dy, dx, 0.0)
                q_n = _shifted(n, dy, dx, 0.0)
                q_v = _shifted(v, dy, dx, 0.0)
                q_var = _shifted(var, dy, dx, 0.0)
                offset = q_p - p
                facing = np.maximum(np.einsum("...i,...i->...", n, q_n), 0.0) ** NORMAL_POWER
                plane = np.abs(np.einsum("...i,...i->...", n, offset))
                tol = PLANE_TOLERANCE * np.sqrt(np.einsum("...i,...i->...", offset, offset)) + 1e-4
                w = ky * kx * q_ok * facing * np.exp(-(plane / tol) ** 2)
                w = w * np.exp(-np.abs(q_v[..., :3] @ LUMINANCE - lum) / scale)
                total += w[..., None] * q_v
                total_var += w * w * q_var
                weight += w
        keep = ok & (weight > 0)
        safe = np.where(keep, weight, 1.0)
        v = np.where(keep[..., None], total / safe[..., None], v)
        var = np.where(keep, total_var / (safe * safe), var)
    return v.astype(np.float32), var.astype(np.float32)

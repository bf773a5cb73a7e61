"""Edge-aware à-trous filtering of a noisy per-pixel estimate (numpy reference of
``render/shaders/denoise.glsl``).

The ray-traced gather gives each traced pixel a Monte Carlo mean and the variance of that mean.
The spatial part of SVGF (Schied et al. 2017) removes the remaining noise without blurring what
is real: ``iterations`` passes of a 5 × 5 B3-spline kernel whose taps are 2^i pixels apart, each
tap weighted by

* geometry: same surface only — normal term max(n·n_q, 0)^NORMAL_POWER times the plane term
  exp(−(|n·(p_q − p)| / (PLANE_TOLERANCE·|p_q − p| + 1e-4))²) (as ``upsample``);
* luminance: exp(−|l_p − l_q| / (SIGMA_LUMINANCE·√(var_p + var_q) + ε)), var_p the 3 × 3
  prefiltered variance of p (SVGF) and var_q the tap's own, so differences larger than the
  noise of both (contact shadows, light gradients) survive while differences of the noise's
  size are averaged away. SVGF tests against var_p alone; on one frame of few rays that loses
  light: a point whose rays missed a small bright source (variance ~0) refuses the neighbours
  that found it, which keep their spike only for themselves, so the filtered mean drops — by
  4× for a wall lit by a spot's glossy reflection off a metal floor. With var_q a noisy
  neighbour is taken as noise by everyone.

A cell whose mean is already known well enough is left as it is: when the standard error of
its mean (the prefiltered variance's square root) is within ``NOISE_TARGET`` (2%) of its
value, a pass keeps it instead of averaging it with its neighbours. The filter's weights keep
what differs by more than the noise, but a smooth darkening into a corner or under a contact
differs from its neighbours by less than that over a tap 4–8 cells away, and averaging it
away was the preview's largest Diffuse Indirect error where the gather is already quiet:
against Cycles at its default light paths (160 × 120, Combined relative L1) the box 0.0288 →
0.0258, the hall 0.0582 → 0.0575, the textured room 0.0331 → 0.0320, the emissive room
0.0466 → 0.0462, the HDRI courtyard 0.0109 → 0.0108 (docs/gi_pipeline.md "Where a preview's
time goes"). A target of 3% gained more on the box (0.0253) but lost on the HDRI courtyard
(0.0119), 1% gained less everywhere; the raw variance instead of the prefiltered one left
the courtyard's cells whose rays all missed the sun unfiltered (0.0264).

Two signals are filtered side by side with the same geometry weights: the RGB light
(luminance test on its luminance) and a scalar (ambient occlusion, its own test). Variance is
filtered with the squared weights (the variance of the weighted mean), so later
passes trust the already smoothed values more. Pixels that see no surface take no part.
Deterministic: no randomness, fixed order of taps.
"""
from __future__ import annotations

import numpy as np

from ..gi.exact_indirect import LUMINANCE

KERNEL = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
NORMAL_POWER = 32
PLANE_TOLERANCE = 0.1
SIGMA_LUMINANCE = 4.0
NOISE_TARGET = 0.02  # a cell is settled when its mean's standard error is within 2% of it
_EPSILON = 1e-6


def _shifted(image: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """image[y + dy, x + dx] with ``fill`` outside (same shape as ``image``)."""
    out = np.full_like(image, fill)
    h, w = image.shape[:2]
    if abs(dy) >= h or abs(dx) >= w:
        return out
    ys = slice(max(0, -dy), min(h, h - dy))
    xs = slice(max(0, -dx), min(w, w - dx))
    ys_src = slice(max(0, dy), min(h, h + dy))
    xs_src = slice(max(0, dx), min(w, w + dx))
    out[ys, xs] = image[ys_src, xs_src]
    return out


GAUSS_3 = np.array([0.25, 0.5, 0.25])


def _blurred(variance: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(H, W, 2) variance averaged over each valid pixel's valid 3 × 3 neighbours (Gaussian
    weights), as SVGF prefilters it: one point's own estimate from a few rays is itself noisy —
    a point whose rays all missed a small bright patch reports ~0 variance and would refuse its
    neighbours."""
    total = np.zeros_like(variance)
    weight = np.zeros(variance.shape[:2])
    for a, ky in enumerate(GAUSS_3):
        for b, kx in enumerate(GAUSS_3):
            q_ok = _shifted(ok, a - 1, b - 1, False) * ky * kx
            total += q_ok[..., None] * _shifted(variance, a - 1, b - 1, 0.0)
            weight += q_ok
    return np.where(ok[..., None], total / np.maximum(weight, 1e-30)[..., None], variance)


def atrous_filter(values: np.ndarray, variance: np.ndarray, valid: np.ndarray,
                  position: np.ndarray, normal: np.ndarray, iterations: int = 4,
                  sigma_luminance: float = SIGMA_LUMINANCE) -> tuple[np.ndarray, np.ndarray]:
    """Filter ``values`` along surfaces.

    Parameters
    ----------
    values : (H, W, 4) float, per pixel the mean light (RGB) and a scalar signal (e.g. AO).
    variance : (H, W, 2) float ≥ 0, the variance of the light's luminance mean and of the
        scalar's mean.
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
        signal = np.stack([v[..., :3] @ LUMINANCE, v[..., 3]], axis=-1)
        blurred = _blurred(var, ok)
        settled = np.sqrt(np.maximum(blurred, 0.0)) <= NOISE_TARGET * np.abs(signal)  # (H, W, 2)
        total = np.zeros_like(v)
        total_var = np.zeros_like(var)
        weight = np.zeros(var.shape)
        for a, ky in enumerate(KERNEL):
            for b, kx in enumerate(KERNEL):
                dy, dx = (a - 2) * step, (b - 2) * step
                q_p = _shifted(p, dy, dx, 0.0)
                q_v = _shifted(v, dy, dx, 0.0)
                offset = q_p - p
                facing = np.maximum(np.einsum("...i,...i->...", n, _shifted(n, dy, dx, 0.0)), 0.0)
                plane = np.abs(np.einsum("...i,...i->...", n, offset))
                tol = PLANE_TOLERANCE * np.sqrt(np.einsum("...i,...i->...", offset, offset)) + 1e-4
                geometry = (ky * kx * _shifted(ok, dy, dx, False) * facing ** NORMAL_POWER
                            * np.exp(-(plane / tol) ** 2))
                q_signal = np.stack([q_v[..., :3] @ LUMINANCE, q_v[..., 3]], axis=-1)
                q_var = _shifted(var, dy, dx, 0.0)
                scale = sigma_luminance * np.sqrt(np.maximum(blurred + q_var, 0.0)) + _EPSILON
                w = geometry[..., None] * np.exp(-np.abs(q_signal - signal) / scale)  # (H, W, 2)
                total[..., :3] += w[..., :1] * q_v[..., :3]
                total[..., 3] += w[..., 1] * q_v[..., 3]
                total_var += w * w * q_var
                weight += w
        keep = ok[..., None] & (weight > 0) & ~settled
        safe = np.where(keep, weight, 1.0)
        full_safe = np.concatenate([np.repeat(safe[..., :1], 3, axis=-1), safe[..., 1:]], axis=-1)
        full_keep = np.concatenate([np.repeat(keep[..., :1], 3, axis=-1), keep[..., 1:]], axis=-1)
        v = np.where(full_keep, total / full_safe, v)
        var = np.where(keep, total_var / (safe * safe), var)
    return v.astype(np.float32), var.astype(np.float32)

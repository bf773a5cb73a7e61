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

The taps' weighted mean is biased wherever the taps lie on one side of the cell and the
light slopes: at a corner or under a contact the light falls towards the edge, and every tap
is farther from it, so the mean is brighter (on the box a band under the ceiling read +6..+17%
of Combined; at one bounce the filter alone took it from +1..4% to +6..26%). So each pass
fits a plane through the taps instead — weighted least squares of v ≈ c + g·(s, u), (s, u) the
tap's place in the 5 × 5 window (``_fit``; the taps of one surface, which the geometry
weights keep, lie on a plane, near enough linear in the image over a window) — and keeps c: the weighted mean where the
taps surround the cell, the level extrapolated along the slope where they do not. The slope is
damped by RIDGE × the taps' mean squared distance, so taps along a line (a thin strip) give no
slope and noise is not extrapolated far. Against Cycles (160 × 120, Combined relative L1):
box 0.0249 → 0.0241, hall 0.0575 → 0.0564, textured room 0.0320 → 0.0319, emissive room
0.0462 → 0.0460, HDRI courtyard 0.0108 → 0.0105. A smaller damping (0.02, 0) kept a corner's
level better on a synthetic slope but left the glossy gather noisier. The glossy gathers keep
the weighted mean (``fit=False``): at 8 rays a point the slope they would extrapolate is
mostly noise (the GPU's and numpy's previews, equal to 2% with the mean, drifted 2.3% apart
with the fit).

The light changes over about the distance at which the point's rays meet the scene: Ward's
irradiance cache trusts a record within a share of the harmonic mean of its rays' hit
distances. A crease, a contact or a narrow slot bends the light within a few cells, where the
taps' plane fit (reaching up to eight cells) cannot follow it, and on the open surface the
same point's light is flat over metres. So the gather hands each point its **reach** R (that
harmonic mean, a miss counting as infinitely far: ``exact_indirect.indirect_and_ao``), and a
tap q of a point p with a reach is weighed by exp(−(|p_q − p| / (REACH · R))²), R the smaller
of the two points' reaches (a hole, or a point whose rays all missed, has none: only the
other's bounds; a hole takes one once the first pass fills it: the harmonic mean of its taps'
reaches, by their weights). On the columned hall at 640 × 480 the error against Cycles' default
light paths fell 0.10118 → 0.10028, under Cycles 16 spp + OIDN's 0.10047; of six scenes only the
emissive room's rose, by 0.4% (docs/gi_pipeline.md "The filter's taps within the gather points'
reach").

Two signals are filtered side by side with the same geometry weights: the RGB light
(luminance test on its luminance) and a scalar (ambient occlusion, its own test). The light's
weight takes the scalar's test as well, exp(−|a_p − a_q| / (SIGMA_LUMINANCE·√(var_p + var_q) +
AO_TOLERANCE)): where the occlusion changes by far more than its noise (a slot between a
ceiling and a panel under it, a contact), the light changes too, often by more than its own
noisier test can tell, and a tap across that edge carried the bright slot's light a few cells
onto the open ceiling (docs/gi_pipeline.md "Occlusion guides the light's filter"). The
tolerance keeps a smooth darkening toward a wall, which differs over a tap by more than the
AO's small noise but by little, from cutting the light's taps (without it the room of metals'
one-bounce Diffuse Indirect got noisier). Where the scalar is 0 everywhere (the glossy
gathers, the world's light) its test is 1. Variance is
filtered with the squared weights (the variance of the weighted mean), so later
passes trust the already smoothed values more. Pixels that see no surface take no part.
Deterministic: no randomness, fixed order of taps.
"""
from __future__ import annotations

import numpy as np

from ..gi.exact_indirect import LUMINANCE
from ..scene.short_axis import all_along

KERNEL = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
NORMAL_POWER = 32
PLANE_TOLERANCE = 0.1
SIGMA_LUMINANCE = 4.0
# the glossy gathers' (8 rays a point, the weighted mean): a narrower luminance test keeps the
# reflections' detail (docs/gi_pipeline.md "The glossy gathers' luminance test")
GLOSSY_SIGMA_LUMINANCE = 2.0
NOISE_TARGET = 0.02  # a cell is settled when its mean's standard error is within 2% of it
RIDGE = 0.25  # the local fit's slope damping, × the taps' mean squared distance
_EPSILON = 1e-6
# the scalar's (AO's) test on the light's weights tolerates this much more than the scalar's
# noise: an occlusion's edge (a slot, a contact) differs by far more, a smooth darkening over
# a tap by less (module doc)
AO_TOLERANCE = 0.1
# a tap farther from a point than REACH × the smaller of the two points' reaches (the harmonic
# mean of their rays' hit distances) counts for little (module doc)
REACH = 0.25
# The first pass over a grid with holes stretches KERNEL over HOLE_SPREAD × its width: the
# sparse gather traces a lattice of every other cell, so the pass reaches as many traced taps
# as a dense pass reaches cells, and each hole is filled from the 16-20 traced cells of a
# 9 × 9 window instead of the 4-6 of a 5 × 5 (docs/gi_pipeline.md "Gathers at fewer points")
HOLE_SPREAD = 2
# A hole's guide (``_hole_guide``) needs its traced 3 × 3 neighbours' same-surface weights to
# come to more than this (of the 0.75 of eight on its surface): fewer, and its taps are weighed
# by geometry alone
GUIDE_WEIGHT = 0.05


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


def _kernel(spread: int) -> np.ndarray:
    """KERNEL stretched over ``spread`` × its width: (4 spread + 1,) taps, KERNEL linearly
    interpolated at (tap − 2 spread) / spread (denoise.glsl ``kernel_at``)."""
    return np.interp(np.arange(-2 * spread, 2 * spread + 1) / spread, np.arange(-2, 3), KERNEL)


def _blurred(variance: np.ndarray, ok: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 2) variance averaged over each valid pixel's valid 3 × 3 neighbours (Gaussian
    weights), as SVGF prefilters it: one point's own estimate from a few rays is itself noisy —
    a point whose rays all missed a small bright patch reports ~0 variance and would refuse its
    neighbours. ``at`` (default ``ok``): the pixels given the average (a hole, not ``ok``
    itself, takes its ``ok`` neighbours'), where they have any."""
    at = ok if at is None else at
    total = np.zeros_like(variance)
    weight = np.zeros(variance.shape[:2])
    for a, ky in enumerate(GAUSS_3):
        for b, kx in enumerate(GAUSS_3):
            q_ok = _shifted(ok, a - 1, b - 1, False) * ky * kx
            total += q_ok[..., None] * _shifted(variance, a - 1, b - 1, 0.0)
            weight += q_ok
    averaged = at & (weight > 0.0)
    return np.where(averaged[..., None], total / np.maximum(weight, 1e-30)[..., None], variance)


def _hole_guide(signal: np.ndarray, sampled: np.ndarray, hole: np.ndarray, position: np.ndarray,
                normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((H, W, 2) guide, (H, W, 2) its spread, (H, W) bool guided): per ``hole`` the mean
    ``signal`` (light's luminance, scalar) of its ``sampled`` 3 × 3 neighbours on its surface
    (GAUSS_3 × ``_surface_weight``) and their variance about it, where their weights come to
    more than GUIDE_WEIGHT. The first pass compares its taps with the guide as a traced cell's
    with its own light, the spread added to the noise it allows: the light may slope across
    the neighbours by more than their noise (module doc)."""
    total = np.zeros_like(signal)
    squares = np.zeros_like(signal)
    weight = np.zeros(signal.shape[:2])
    for a, ky in enumerate(GAUSS_3):
        for b, kx in enumerate(GAUSS_3):
            if a == 1 and b == 1:
                continue
            w = ky * kx * _shifted(sampled, a - 1, b - 1, False) * \
                _surface_weight(position, normal, a - 1, b - 1)
            q = _shifted(signal, a - 1, b - 1, 0.0)
            total += w[..., None] * q
            squares += w[..., None] * q * q
            weight += w
    guided = hole & (weight > GUIDE_WEIGHT)
    norm = np.maximum(weight, 1e-30)[..., None]
    guide = total / norm
    spread = np.maximum(squares / norm - guide * guide, 0.0)
    return (np.where(guided[..., None], guide, 0.0), np.where(guided[..., None], spread, 0.0),
            guided)


def _fit(moments, spread, light, scalar, fit: bool = True):
    """The local linear fit's value at the centre and its variance, per pixel: the weighted
    least-squares plane v ≈ c + g·(s, u) through the taps, whose c is the weighted mean where
    the taps surround the centre and corrects it where they lie on one side (a corner, a
    contact: the mean of one side's taps is biased by the light's slope). moments (…, 2, 6):
    Σ w·(1, s, u, s², su, u²) per signal; spread: the same of w²·var_q; light (…, 3, 3):
    Σ w·(1, s, u)·rgb; scalar (…, 3): Σ w·(1, s, u)·scalar. The slope is damped by RIDGE ×
    the mean squared distance (no slope where the taps lie along a line). Returns ((…, 4)
    values, (…, 2) variances): c ≥ 0, and its variance Σ h_q² var_q with h_q the fit's weight
    of tap q. fit False: the weighted mean (c alone, no slope)."""
    out_v = np.zeros(light.shape[:-2] + (4,))
    out_var = np.zeros(moments.shape[:-1])
    for k in range(2):
        m0, ms, mu, mss, msu, muu = np.moveaxis(moments[..., k, :], -1, 0)
        # (+ a hair of m0: a cell whose only tap is itself keeps its value, in float32 too)
        damp = RIDGE * (mss + muu) * 0.5 + 1e-4 * m0
        a, bb, c = mss + damp, msu, muu + damp
        # the first row of the inverse of [[m0, ms, mu], [ms, a, bb], [mu, bb, c]] (cofactors)
        c0 = a * c - bb * bb
        c1 = mu * bb - ms * c
        c2 = ms * bb - mu * a
        det = m0 * c0 + ms * c1 + mu * c2
        safe = np.where(det > 0.0, det, 1.0)
        row = np.stack([c0, c1, c2], axis=-1) / safe[..., None]  # (…, 3)
        if not fit:
            row = np.stack([1.0 / np.where(m0 > 0.0, m0, 1.0), 0.0 * m0, 0.0 * m0], axis=-1)
        if k == 0:
            out_v[..., :3] = np.einsum("...i,...ic->...c", row, light)
        else:
            out_v[..., 3] = np.einsum("...i,...i->...", row, scalar)
        q0, qs, qu, qss, qsu, quu = np.moveaxis(spread[..., k, :], -1, 0)
        r0, r1, r2 = np.moveaxis(row, -1, 0)
        out_var[..., k] = (r0 * r0 * q0 + r1 * r1 * qss + r2 * r2 * quu
                           + 2.0 * (r0 * r1 * qs + r0 * r2 * qu + r1 * r2 * qsu))
    return np.maximum(out_v, 0.0), np.maximum(out_var, 0.0)


SAME_SURFACE = 0.5  # a neighbour whose same-surface weight is above this is on the surface


def _surface_weight(position, normal, dy: int, dx: int) -> np.ndarray:
    """(H, W) per cell the same-surface weight of the cell (dy, dx) away, seen from the cell
    (its normal and tangent plane): max(n·n_q, 0)^NORMAL_POWER ×
    exp(−(|n·(p_q − p)| / (PLANE_TOLERANCE·|p_q − p| + 1e-4))²), the filter's geometry terms."""
    offset = _shifted(position, dy, dx, 0.0) - position
    facing = np.maximum(np.einsum("...i,...i->...", normal, _shifted(normal, dy, dx, 0.0)), 0.0)
    plane = np.abs(np.einsum("...i,...i->...", normal, offset))
    tol = PLANE_TOLERANCE * np.sqrt(np.einsum("...i,...i->...", offset, offset)) + 1e-4
    return facing ** NORMAL_POWER * np.exp(-(plane / tol) ** 2)


def _giver_weights(position, normal, ok, dy: int, dx: int) -> np.ndarray:
    """``_surface_weight``, 0 where the cell or the one (dy, dx) away is not ``ok``."""
    return _surface_weight(position, normal, dy, dx) * ok * _shifted(ok, dy, dx, False)


def spread_spikes(values: np.ndarray, variance: np.ndarray, valid: np.ndarray,
                  position: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values, variance) with each cell's light above its neighbours' spread over its
    surface before the filter (docs/gi_pipeline.md "A known defect: a dotted lattice in the
    filtered glossy gather"): a cell whose luminance exceeds that of the brightest of its
    3 × 3 neighbours on its surface (same-surface weight above ``SAME_SURFACE``) — an isolated
    spike, not a highlight's edge, whose brighter inside is beside it — gives that excess (its
    rgb in proportion) to the cells of its 5 × 5 window, KERNEL × its same-surface weights
    normalised over them (itself among them), so the light is kept; each receiver's variance
    grows by its share × the giver's variance. The filter's passes would otherwise leave a
    spike's light on a lattice of their steps: the spike keeps it (its neighbours differ by
    more than its prefiltered noise) while the cells one step away take it through its own
    variance. The scalar (AO) is not moved."""
    v = np.asarray(values, np.float64).copy()
    var = np.asarray(variance, np.float64).copy()
    ok = np.asarray(valid, bool)
    p = np.asarray(position, np.float64)
    n = np.asarray(normal, np.float64)
    light = v[..., :3] @ LUMINANCE
    near = np.zeros(ok.shape)  # the brightest same-surface neighbour's light
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                same = _giver_weights(p, n, ok, dy, dx) > SAME_SURFACE
                near = np.maximum(near, np.where(same, _shifted(light, dy, dx, 0.0), 0.0))
    excess = np.where(ok, np.maximum(light - near, 0.0), 0.0)
    given = np.where(light > 0, excess / np.maximum(light, 1e-30), 0.0)[..., None] * v[..., :3]
    offsets = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]
    kernel = {(dy, dx): KERNEL[dy + 2] * KERNEL[dx + 2] * _giver_weights(p, n, ok, dy, dx)
              for dy, dx in offsets}
    total = sum(kernel.values())
    share = {d: np.where(total > 0, k / np.maximum(total, 1e-30), 0.0) for d, k in kernel.items()}
    giving = excess > 0
    out = v.copy()
    out[..., :3] -= given
    spread_var = np.where(giving, var[..., 0], 0.0)
    for (dy, dx), w in share.items():  # the receiver q + (dy, dx) of the giver q
        out[..., :3] += _shifted(w[..., None] * given, -dy, -dx, 0.0)
        var[..., 0] += _shifted(w * spread_var, -dy, -dx, 0.0)
    return out, var


def _reach_weight(position: np.ndarray, reach: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """(H, W) the weight of the tap (dy, dx) away by the reaches (``atrous_filter``'s reach):
    exp(−(|p_q − p| / (REACH · R))²), R the tap's reach where it is smaller and has one, 1 where
    the pixel has none."""
    q_reach = _shifted(reach, dy, dx, 0.0)
    r = np.where((q_reach > 0.0) & (q_reach < reach), q_reach, reach)
    offset = _shifted(position, dy, dx, 0.0) - position
    d2 = np.einsum("...i,...i->...", offset, offset)
    return np.where(reach > 0.0, np.exp(-d2 / np.maximum(REACH * r, 1e-30) ** 2), 1.0)


def atrous_filter(values: np.ndarray, variance: np.ndarray, valid: np.ndarray,
                  position: np.ndarray, normal: np.ndarray, iterations: int = 4,
                  sigma_luminance: float = SIGMA_LUMINANCE,
                  fit: bool = True, holes: np.ndarray | None = None,
                  unseen: np.ndarray | None = None,
                  noise_target: float = NOISE_TARGET,
                  reach: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Filter ``values`` along surfaces.

    Parameters
    ----------
    values : (H, W, 4) float, per pixel the mean light (RGB) and a scalar signal (e.g. AO).
    variance : (H, W, 2) float ≥ 0, the variance of the light's luminance mean and of the
        scalar's mean.
    valid : (H, W) bool, pixels that see a surface (others are left as they are).
    position, normal : (H, W, 3) world-space G-buffer of those pixels (metres, unit normals).
    iterations : passes with tap spacing 1, 2, 4, …
    fit : the local linear fit (``_fit``); False: the taps' weighted mean (the glossy
        gathers: 8 rays a point are too noisy to extrapolate a slope from).
    holes : (H, W) bool, valid pixels with no value of their own (the cells the sparse gather
        left out, ``sparse_gather``): the first pass gives them the fit of their taps (no
        tap themselves; the light compared with a tap's is their traced neighbours' on their
        surface, ``_hole_guide``, else none), later passes filter them as the rest.
        With any hole the first pass's kernel is stretched over HOLE_SPREAD × its width
        (``_kernel``), for every cell.
    unseen : (H, W) bool, pixels whose light no pass shows (a metal's point, whose gather
        drew its scalar, the AO, alone: ``sparse_gather.ray_counts``): they are no taps of the
        light of the pixels that show it (their scalar still is), so their few rays' noise
        does not reach a diffuse neighbour through the luminance test's weights.
    noise_target : a pixel whose mean's standard error is within this share of its value is
        settled, kept as it is (``NOISE_TARGET``); 0: only a pixel with no variance is (the
        world's light: ``passes.world_filtered``).
    reach : (H, W) float ≥ 0, each pixel's reach (metres; 0: none — a hole has none until
        the pass that fills it gives it its taps' harmonic mean reach, by the light's weights):
        a pixel with a reach weighs its taps by how far they lie within REACH × the smaller of
        their two reaches (the module doc); None: no bound.

    Returns
    -------
    (values, variance) filtered, float32, same shapes.
    """
    v = np.asarray(values, np.float64).copy()
    var = np.asarray(variance, np.float64).copy()
    ok = np.asarray(valid, bool)
    p = np.asarray(position, np.float64)
    n = np.asarray(normal, np.float64)
    hole = np.zeros(ok.shape, bool) if holes is None else np.asarray(holes, bool) & ok
    hidden = np.zeros(ok.shape, bool) if unseen is None else np.asarray(unseen, bool) & ok
    own = None if reach is None else np.where(ok & ~hole, np.asarray(reach, np.float64), 0.0)
    for it in range(iterations):
        step = 1 << it
        # the first pass over a grid with holes spans the traced lattice's spacing
        stretch = HOLE_SPREAD if it == 0 and hole.any() else 1
        signal = np.stack([v[..., :3] @ LUMINANCE, v[..., 3]], axis=-1)
        sampled = ok & ~hole  # the taps (a hole is none until the first pass fills it)
        blurred = _blurred(var, sampled, ok)
        # a hole's light is its traced neighbours' (_hole_guide); one without any on its
        # surface weighs its taps by geometry alone
        guide, guide_spread, guided = _hole_guide(signal, sampled, hole, p, n)
        signal = np.where(guided[..., None], guide, signal)
        free = hole & ~guided
        settled = np.sqrt(np.maximum(blurred, 0.0)) <= noise_target * np.abs(signal)  # (H, W, 2)
        settled &= ~hole[..., None]
        # per signal (light, scalar): the weighted sums of the local linear fit (_fit)
        moments = np.zeros(var.shape + (6,))     # Σ w·(1, s, u, s², su, u²)
        spread = np.zeros(var.shape + (6,))      # the same moments of w²·var_q
        light = np.zeros(var.shape[:2] + (3, 3))  # Σ w·(1, s, u)·rgb_q
        nearness = np.zeros(var.shape[:2])  # Σ w / R_q of the light's taps (a hole's reach)
        scalar = np.zeros(var.shape[:2] + (3,))   # Σ w·(1, s, u)·scalar_q
        taps = _kernel(stretch)
        reach = 2 * stretch
        for a, ky in enumerate(taps):
            for b_, kx in enumerate(taps):
                dy, dx = (a - reach) * step, (b_ - reach) * step
                q_v = _shifted(v, dy, dx, 0.0)
                geometry = ky * kx * _shifted(sampled, dy, dx, False) * _surface_weight(p, n, dy, dx)
                if own is not None:
                    geometry = geometry * _reach_weight(p, own, dy, dx)
                q_signal = np.stack([q_v[..., :3] @ LUMINANCE, q_v[..., 3]], axis=-1)
                q_var = _shifted(var, dy, dx, 0.0)
                scale = sigma_luminance * np.sqrt(np.maximum(blurred + q_var + guide_spread, 0.0)) + \
                    _EPSILON
                w = geometry[..., None] * np.where(free[..., None], 1.0,
                                                   np.exp(-np.abs(q_signal - signal) / scale))
                # the light's weight takes the scalar's test too, widened (the module doc)
                w[..., 0] *= np.where(free, 1.0, np.exp(-np.abs(q_signal[..., 1] - signal[..., 1])
                                                        / (scale[..., 1] + AO_TOLERANCE)))
                w[..., 0] *= ~(_shifted(hidden, dy, dx, False) & ~hidden)
                if own is not None:
                    q_reach = _shifted(own, dy, dx, 0.0)
                    nearness += w[..., 0] * np.where(q_reach > 0.0, 1.0 / np.maximum(q_reach, 1e-30), 0.0)
                s = np.full(var.shape[:2], (b_ - reach) / stretch)  # the tap's place in the window
                u = np.full(var.shape[:2], (a - reach) / stretch)
                x = np.stack([np.ones_like(s), s, u], axis=-1)  # (H, W, 3)
                quad = np.stack([x[..., 0], s, u, s * s, s * u, u * u], axis=-1)  # (H, W, 6)
                moments += w[..., None] * quad[..., None, :]
                spread += (w * w * q_var)[..., None] * quad[..., None, :]
                light += (w[..., 0:1] * x)[..., :, None] * q_v[..., None, :3]
                scalar += w[..., 1:2] * x * q_v[..., 3:4]
        fitted, fitted_var = _fit(moments, spread, light, scalar, fit)
        keep = ok[..., None] & (moments[..., 0] > 0) & ~settled
        full_keep = np.concatenate([np.repeat(keep[..., :1], 3, axis=-1), keep[..., 1:]], axis=-1)
        v = np.where(full_keep, fitted, v)
        var = np.where(keep, fitted_var, var)
        if own is not None:  # a hole filled takes its taps' harmonic mean reach
            filled = hole & all_along(keep)
            own = np.where(filled & (nearness > 0.0),
                           moments[..., 0, 0] / np.maximum(nearness, 1e-30), own)
        hole = hole & ~all_along(keep)  # filled
    return v.astype(np.float32), var.astype(np.float32)

"""The diffuse gather at fewer points than its cells where the light is smooth
(docs/gi_pipeline.md "Gathers at fewer points").

The gather's grid (``upsample.sample_pixels``: one cell per stride × stride pixels) is traced
at one cell in four — the cells of odd row and odd column, each the middle of a 2 × 2 block of
cells — and at every other cell whose traced neighbours do not see its own surface around it
(a crease, a contact, a silhouette, a thin part). The cells not traced are holes that the
à-trous filter's first pass fills from its taps (``denoise.atrous_filter(holes=…)``, a pass
stretched to the traced lattice's spacing) before its passes run over the grid as over a dense
one. The cells left out lend their rays to the traced ones: a traced point draws
``SPARSE_RAYS`` × the gather's rays (``sparse_settings``), or fewer where few cells are left
out to lend them. After the first list a second one
(``noisy_holes``) traces the ``EXTRA`` × (valid cells) holes whose fill would carry the most
noise or lie across a light's edge, so the rays go where the image would show it; in all the gather traces about half a
dense gather's rays on the test scenes (0.49–0.56). Last, a cell far brighter than every
traced cell near it (one ray that found a small, very bright patch) is traced again with more
rays (``retrace_spikes``): the filter's first pass would fill every hole around it from it.
Both tracers plan with ``sparse_plan`` and ``noisy_holes`` and trace with ``sparse_settings``,
so where their G-buffers agree they trace the same points with the same sample ids; each plans
on its own (the GPU's raster, numpy's ray cast), and a borderline cell one traces and the
other fills differs by its noise.

Numpy only.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..gi.exact_indirect import LUMINANCE
from ..scene.short_axis import norm3

__all__ = ["AO_RAYS", "EXTRA", "MATCH", "SPARSE_GLOSSY_STRIDE", "SPARSE_RAYS", "gather_counts",
           "gather_lists", "glossy_cells", "noisy_holes", "ray_counts", "retrace_spikes",
           "sparse_glossy_settings", "sparse_plan", "sparse_settings", "spikes", "SPIKE",
           "SPIKE_RAYS"]

# Rays per traced point, as a multiple of the gather's (docs/gi_pipeline.md "Gathers at fewer
# points": with the stretched first pass and the second list, 1.5 × them kept the test scenes'
# error within 0.5-4% of twice them at three quarters of their rays, the metal room's Diffuse
# Indirect at its dense gather's)
SPARSE_RAYS = 1.5

# A cell is traced itself when its traced neighbours' same-surface weights come to less than
# MATCH of what they would be all on its surface (a neighbour on the cell's plane with its
# normal weighs 1: max(n·n_q, 0)^32 × exp(-(plane distance / (0.1 |offset| + 1e-4))²), as the
# à-trous filter weighs its taps; a diagonal neighbour counts half): a cell at a crease or a
# silhouette, whose fill would come from one side only, is gathered.
MATCH = 0.5

# the 8 neighbours (row, column offsets) and their share by distance (B-spline-like: the
# diagonal ones count half)
_OFFSETS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)
_SHARE = np.array([0.5 if dr and dc else 1.0 for dr, dc in _OFFSETS])


def _shifted(array: np.ndarray, dr: int, dc: int, fill_value=0) -> np.ndarray:
    """array[r + dr, c + dc] at (r, c) of its first two axes, ``fill_value`` outside."""
    out = np.full_like(array, fill_value)
    h, w = array.shape[:2]
    rs, re = max(0, -dr), min(h, h - dr)
    cs, ce = max(0, -dc), min(w, w - dc)
    if rs < re and cs < ce:
        out[rs:re, cs:ce] = array[rs + dr:re + dr, cs + dc:ce + dc]
    return out


def sparse_plan(valid: np.ndarray, position: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(Hl, Wl) bool: the cells to gather, of the grid's ``valid`` (Hl, Wl) bool cells (those
    seeing a surface) at ``position``, ``normal`` (Hl, Wl, 3) (the gather points and their
    unit normals; row 0 on top)."""
    valid = np.asarray(valid, bool)
    position = np.asarray(position, np.float64)
    normal = np.asarray(normal, np.float64)
    rows, cols = np.indices(valid.shape)
    base = valid & (rows % 2 == 1) & (cols % 2 == 1)
    matched = np.zeros(valid.shape)
    present = np.zeros(valid.shape)
    for share, (dr, dc) in zip(_SHARE, _OFFSETS):
        there = _shifted(base, dr, dc, False)
        offset = _shifted(position, dr, dc) - position
        facing = np.maximum((normal * _shifted(normal, dr, dc)).sum(axis=-1), 0.0) ** 32
        plane = np.abs((normal * offset).sum(axis=-1))
        tol = 0.1 * norm3(offset) + 1e-4
        matched += np.where(there, share * facing * np.exp(-(plane / tol) ** 2), 0.0)
        present += share * there
    return base | (valid & (matched < MATCH * present))


# The second list's size, as a fraction of the grid's valid cells (docs/gi_pipeline.md "Gathers
# at fewer points": 5% took the metal room's Diffuse Indirect from 0.1192 to 0.1067 and the
# emissive room's Combined from 0.0377 to 0.0356, for a tenth of a dense gather's rays)
EXTRA = 0.05


def noisy_holes(traced: np.ndarray, valid: np.ndarray, variance: np.ndarray,
                light: np.ndarray | None = None) -> np.ndarray:
    """(Hl, Wl) bool: the holes to gather too — the ``EXTRA`` × (valid cells) holes whose fill
    would be furthest off: the variance of the mean of their ``traced`` 3 × 3 neighbours, from
    those neighbours' ``variance`` (Hl, Wl) (of their light's luminance mean), plus how far
    their ``light`` (Hl, Wl, ≥3 RGB; None: not counted) spreads beyond that noise (the
    variance of their luminances but the brightest's, less their mean variance): a hole
    beside a light's edge (a lit band one cell wide) lies on one side of it, and its fill can
    only guess which.
    Absolute, not relative to the light: the image's error (relative L1 sums absolute
    differences) is largest where the fill's is, whether the light there is bright or dim.
    Ties go to the first in row-major order."""
    traced = np.asarray(traced, bool)
    var = np.where(traced, np.asarray(variance, np.float64), 0.0)
    lum = np.zeros(var.shape) if light is None else \
        np.where(traced, np.asarray(light, np.float64)[..., :3] @ LUMINANCE, 0.0)
    total = np.zeros(var.shape)
    count = np.zeros(var.shape)
    first = np.zeros(var.shape)
    second = np.zeros(var.shape)
    brightest = np.zeros(var.shape)
    noisiest = np.zeros(var.shape)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            total += _shifted(var, dr, dc)
            count += _shifted(traced, dr, dc, False)
            first += _shifted(lum, dr, dc)
            second += _shifted(lum * lum, dr, dc)
            brightest = np.maximum(brightest, _shifted(lum, dr, dc))
            noisiest = np.maximum(noisiest, _shifted(var, dr, dc))
    holes = np.asarray(valid, bool) & ~traced & (count > 0)
    wanted = min(int(EXTRA * np.count_nonzero(valid)), int(np.count_nonzero(holes)))
    out = np.zeros(traced.shape, bool)
    if wanted > 0:
        n = np.maximum(count, 1.0)
        # the spread of the neighbours but the brightest: an edge has two on each side of it,
        # a spike (one ray that found a small bright patch: ``retrace_spikes``) one alone
        rest = np.maximum(count - 1.0, 1.0)
        spread = np.where(count >= 3.0, (second - brightest ** 2) / rest -
                          ((first - brightest) / rest) ** 2 - total / n, 0.0)
        # the noise of the fill but the noisiest neighbour's: holes picked for one neighbour
        # that caught a rare bright ray (its variance is as high as its light) would leave
        # the holes not picked filled from the dimmer ones, the image's light short
        noise = np.where(count >= 2.0, (total - noisiest) / rest, total) / n
        error = np.where(holes, noise + np.maximum(spread, 0.0), -1.0).ravel()
        out.ravel()[np.argsort(-error, kind="stable")[:wanted]] = True
    return out


def sparse_settings(settings, valid: int | None = None, traced: int | None = None):
    """``settings`` (a ``gather.GatherSettings``) as the sparse gather's traced points use
    them: ``SPARSE_RAYS`` × its rays, rounded — or, given the counts of ``valid`` cells and of
    the first list's ``traced`` ones, only as many more as the holes lend: at most
    valid / traced × its rays, so the sparse gather never traces more than a dense one. Where
    nearly every cell is traced (a bumpy terrain of sub-pixel triangles, whose neighbours all
    fail the same-surface test: 87% of a 140k-triangle glTF diorama's cells at 160 × 120),
    1.5 × the rays everywhere made the gather 1.3 × a dense one's for the same error."""
    share = SPARSE_RAYS
    if valid is not None and traced:
        share = min(SPARSE_RAYS, valid / traced)
    return replace(settings, rays=max(1, round(settings.rays * share)))


# The glossy gather is sparse too where the gathers' cells are at most 2 × 2 pixels (GI
# Resolution Full and Half, Auto up to 480 × 360): ``sparse_plan``'s cells, each with
# ``SPARSE_RAYS`` × its rays, no second list (``glossy_cells``; docs/gi_pipeline.md "Glossy
# gathers at fewer points": at 160 × 120 the previews took 7-29% less time for 0.3-7% more
# error, the room of metals the most of both; "Glossy gathers at fewer points at 2 × 2
# pixels a cell": at 320 × 240 the same error or less, the glossy gather a fifth of a metal
# scene's preview before). At one cell per 3 × 3 pixels (640 × 480) the glossy gather is a
# few percent of the frame: sparse, it saved no time and added 0.1-0.6% error
SPARSE_GLOSSY_STRIDE = 2


def glossy_cells(valid: np.ndarray, position: np.ndarray, normal: np.ndarray, stride: int,
                 sparse: bool, diffuse: np.ndarray | None = None,
                 plan: np.ndarray | None = None) -> np.ndarray:
    """(Hl, Wl) bool: the cells the Glossy Indirect gather traces — with ``sparse`` (Sparse
    Gathers) at a ``stride`` up to SPARSE_GLOSSY_STRIDE ``sparse_plan``'s and every cell whose
    surface shows no diffuse light (``diffuse`` (Hl, Wl) bool, None: all show it; a full
    metal, whose light is all glossy: filled, the room of metals' Combined read 0.0329 against
    0.0264 at one bounce), the others holes that the filter's first pass fills; else every
    ``valid`` cell. plan : ``sparse_plan``'s cells, made already (None: made here)."""
    valid = np.asarray(valid, bool)
    if sparse and stride <= SPARSE_GLOSSY_STRIDE:
        metal = np.zeros(valid.shape, bool) if diffuse is None else valid & ~np.asarray(diffuse, bool)
        return (sparse_plan(valid, position, normal) if plan is None else plan) | metal
    return valid


def sparse_glossy_settings(settings, valid: int, traced: int):
    """``settings`` with the glossy rays of a sparse glossy gather's traced points: as
    ``sparse_settings``' rays, SPARSE_RAYS × them at most, only as many more as the holes
    lend."""
    share = min(SPARSE_RAYS, valid / traced) if traced else 1.0
    return replace(settings, glossy_rays=max(1, round(settings.glossy_rays * share)))


# Rays of a gather point whose surface shows no diffuse light (Diffuse Color 0: a full metal, a
# black surface). The Diffuse Indirect pass and Combined take the gathered light × Diffuse
# Color (``passes.finish_passes``), so there the gather feeds the AO pass alone, which these
# rays and the filter hold (docs/gi_pipeline.md "Gather points on metals trace AO only").
AO_RAYS = 8


def ray_counts(cells: np.ndarray, diffuse: np.ndarray, rays: int) -> np.ndarray:
    """(Hl, Wl) int: the rays each of ``cells`` (bool) draws, 0 elsewhere: ``rays`` where its
    surface shows diffuse light (``diffuse``, (Hl, Wl) bool), ``AO_RAYS`` (at most ``rays``)
    where it does not."""
    counts = np.where(np.asarray(diffuse, bool), rays, min(AO_RAYS, rays))
    return np.where(np.asarray(cells, bool), counts, 0)


def gather_counts(counts: np.ndarray, values: np.ndarray, variance: np.ndarray, settings,
                  trace, more=()) -> None:
    """Gathers the cells of ``counts`` (``ray_counts``) into ``values`` (Hl, Wl, 4) and
    ``variance`` (Hl, Wl, ≥2) in place, one ``trace(cells, settings)`` → ((N, 4), (N, ≥2))
    per count (row-major), each with ``settings.rays`` = that count: a cell drawing all the
    rays draws exactly what it would with one count for all. more : further (Hl, Wl, …)
    arrays, filled from the further (N, …) arrays ``trace`` returns."""
    for count in np.unique(counts[counts > 0]):
        at = counts == count
        for array, got in zip((values, variance, *more),
                              trace(at, replace(settings, rays=int(count)))):
            array[at] = got


def gather_lists(traced: np.ndarray, valid: np.ndarray, diffuse: np.ndarray, values: np.ndarray,
                 variance: np.ndarray, settings, trace, more=()) -> np.ndarray:
    """The sparse gather's two lists into ``values`` and ``variance`` in place, as both tracers
    run them: the ``traced`` cells (``sparse_plan``), then the holes ``noisy_holes`` picks among
    those whose surface shows diffuse light (``diffuse``), by the noise of the traced cells
    that show it — each point ``ray_counts`` rays (``settings.rays`` where it shows diffuse
    light) through ``trace`` (``gather_counts``), then the spikes among them again
    (``retrace_spikes``). more : further (Hl, Wl, …) arrays that ``trace`` fills after the
    two (``gather_counts``), from the first two lists (a spike's keeps its first rays').
    Returns every cell traced."""
    gather_counts(ray_counts(traced, diffuse, settings.rays), values, variance, settings, trace,
                  more)
    extra = noisy_holes(traced & diffuse, valid & diffuse, variance[..., 0], values)
    if extra.any():
        gather_counts(ray_counts(extra, diffuse, settings.rays), values, variance, settings,
                      trace, more)
    retrace_spikes((traced | extra) & diffuse, values, variance, settings, trace)
    return traced | extra


# A traced cell whose light is more than SPIKE × that of the brightest traced cell within two
# cells of it is traced again with SPIKE_RAYS × its rays, both estimates merged by their rays
# (docs/gi_pipeline.md "Spikes traced again"). One ray that found a small, very bright patch
# (the lit slot over a ceiling panel, seen from the wall below it) reads as a spike, and the
# sparse filter's first pass fills every hole of its window from it by geometry alone: a
# visible blotch, 25-30% bright over 30 × 15 pixels. Light that is there (a lit band one cell
# wide) reads as much again and keeps its level. Not unbiased: a cell picked for its first
# rays' light keeps a fifth of their weight, so where a few rare rays carry much of the light
# that light reads lower (measured in the doc).
SPIKE = 4.0
SPIKE_RAYS = 4



def spikes(traced: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(Hl, Wl) bool: the ``traced`` cells whose luminance (``values`` (Hl, Wl, ≥3) RGB) is
    above SPIKE × the brightest other traced cell of their 5 × 5 neighbourhood (none there:
    not a spike)."""
    traced = np.asarray(traced, bool)
    light = np.where(traced, np.asarray(values, np.float64)[..., :3] @ LUMINANCE, -1.0)
    near = np.full(light.shape, -1.0)
    for dr in range(-2, 3):
        for dc in range(-2, 3):
            if dr or dc:
                near = np.maximum(near, _shifted(light, dr, dc, -1.0))
    return traced & (near >= 0.0) & (light > SPIKE * np.maximum(near, 0.0)) & (light > 0.0)


def retrace_spikes(traced: np.ndarray, values: np.ndarray, variance: np.ndarray, settings,
                   trace) -> np.ndarray:
    """Traces the ``spikes`` among ``traced`` again with SPIKE_RAYS × ``settings.rays`` (the
    next seed: new samples) through ``trace`` (``gather_counts``' contract) and merges both
    estimates into ``values`` (Hl, Wl, ≥4) and ``variance`` (Hl, Wl, ≥2: the variances of the
    means of the light's luminance and of the scalar; the channels after them are left) in
    place, each mean weighted by its rays. Returns the cells traced again."""
    again = spikes(traced, values)
    if not again.any():
        return again
    more = replace(settings, rays=SPIKE_RAYS * settings.rays, seed=settings.seed + 1)
    first = np.asarray(values[again][:, :4], np.float64)
    first_var = np.asarray(variance[again][:, :2], np.float64)
    second, second_var = (np.asarray(a, np.float64) for a in trace(again, more)[:2])
    share = 1.0 / (1.0 + SPIKE_RAYS)  # the first rays' share of both
    values[again, :4] = share * first + (1.0 - share) * second[:, :4]
    variance[again, :2] = share ** 2 * first_var + (1.0 - share) ** 2 * second_var[:, :2]
    return again

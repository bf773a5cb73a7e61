"""Progressive accumulation of a preview image (numpy only): the viewport's time-sliced
drawing (``render/progressive.py``) splits a full image into *samples* and each sample into
*tiles*, traces one tile of one sample per slice and averages the samples here.

* ``sample_settings`` — one sample's share of the image's rays: ⌈rays / samples⌉ gather rays,
  ⌈glossy rays / samples⌉ glossy rays, ⌈light samples / samples⌉ shadow rays, its own seed;
  ``samples`` of them trace at least the one-shot image's rays.
* ``sample_offset`` — its sub-pixel offset, drawn by importance from Cycles' pixel filter
  inside the pixel (``camera.filter_offsets``, the strata the one-shot image's sub-pixel passes
  use), so the samples' mean is the anti-aliased image, edges included.
* ``tile_camera`` — the camera of a rectangle of the image (an off-axis frustum with the
  offset baked in): its pixels are exactly the image's pixels there.
* ``tile_grid`` — the tiles covering the image, the grid shifted from sample to sample so the
  tiles' borders (the gather's filter sees fewer neighbours there) do not stay in place.
* ``Accumulation`` — per-pixel sums of one pass (light passes as light × colour over colour,
  as Cycles' film divides them) and per-pixel counts, and the filter's tails: each sample's
  sums also go into the neighbours by Cycles' pixel filter at its offset, so ``estimate`` —
  at any sample, as Cycles' viewport shows its film — is the filtered image the one-shot
  image is (``passes.filter_passes``), and fills the pixels no sample reached yet from a
  coarse image; ``finished`` is that image once every sample is in.
* the film (``film=True``): per pixel the samples' world along their camera rays, their
  coverage (``Alpha``) and holdout shares, with the same tails, so ``film_rgba`` composes the
  world behind the geometry as F12's film does (``preview.film``).
* ``SliceSizer`` — the tile size that fits a time budget, from measured slices (a fixed
  cost per slice plus a cost per pixel, fitted by least squares).
"""
from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..scene.camera import filter_offsets
from .film import film_combined
from .gather import GatherSettings
from .passes import PASS_NAMES, filter_coverage, filter_passes, tail_weights
from .upsample import low_shape, same_surface

# The passes made of the gathers: their samples are weighted by the samples behind the
# gathers' sums (``GatherSums``: a later sample's gather filters more rays).
GATHERED = ("Diffuse Indirect", "Glossy Indirect", "Ambient Occlusion")
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
# A light pass is accumulated as light × colour over colour (Cycles' film, passes.finish_passes).
LIGHT_COLOURS = {"Diffuse Direct": "Diffuse Color", "Diffuse Indirect": "Diffuse Color",
                 "Glossy Direct": "Glossy Color", "Glossy Indirect": "Glossy Color"}
SEED_STEP = 7919  # seeds of successive samples: far apart in the hashed sequences
# The samples that trace the gathers: the first GATHER_SAMPLES share the gather rays, the later
# ones trace none and read the gathers' sums (``GatherSums.add`` with 0 rays). Their gathers
# are then whole after a quarter of the default 16 Viewport Samples, and the rest bring the
# edges and the shadows' strata alone (docs/gi_pipeline.md "Viewport samples whose gathers end
# early").
GATHER_SAMPLES = 4
# The quantile of the measured slices that a slice sizer fits into its budget (``SliceSizer``):
# sized by the median, one staged draw in nine ran 25–44 ms against the 30 ms budget
# (docs/gi_pipeline.md "Slices sized by their tail, stages predicted by their longest runs")
TAIL = 0.9
TAIL_LEAST = 8   # slices measured before the quantile is taken
ONE_OFF = 3.0    # a slice this many times the median's ratio to the model waited once
# The last RECENT slices all this much slower than the model: the machine is (another
# process's burst), so the next slices are sized for it at once, not once the quantile of
# the kept ones has moved: a burst ran a dozen staged draws in a row at 33–50 ms
RECENT = 2


def gather_samples(samples: int) -> int:
    """How many of ``samples`` trace the gathers (``GATHER_SAMPLES`` at most)."""
    return max(1, min(samples, GATHER_SAMPLES))


def sample_settings(gather: GatherSettings, light_samples: int, samples: int, index: int,
                    gathering: int | None = None):
    """(GatherSettings, light samples) of sample ``index`` of ``samples``, each with its own
    seed: the first ``gathering`` samples (None: ``gather_samples``) ⌈rays / gathering⌉
    gather rays and ⌈glossy rays / gathering⌉ glossy rays, the later ones none (they read the
    gathers' sums), and every sample ⌈light samples / gathering⌉ shadow rays a light — so the
    gathering samples between them trace the one-shot image's rays and its light samples, and
    the view's first image is near F12's (with ⌈light samples / samples⌉, one stratum a
    sample, its penumbrae stayed noisy for most of the samples: docs/gi_pipeline.md "Every
    sample with a share of the pixel's light samples"). The samples are averaged alike, so
    every one traces as many."""
    if samples < 1:
        raise ValueError(f"samples must be at least 1, not {samples}")
    if not 0 <= index < samples:
        raise ValueError(f"sample index {index} is outside 0..{samples - 1}")
    gathering = gather_samples(samples) if gathering is None else max(1, min(gathering, samples))
    traced = index < gathering
    per = dataclasses.replace(
        gather, rays=max(1, math.ceil(gather.rays / gathering)) if traced else 0,
        glossy_rays=max(1, math.ceil(gather.glossy_rays / gathering)) if traced else 0,
        seed=gather.seed + SEED_STEP * index)
    return per, max(1, math.ceil(light_samples / gathering))


def bayer(side: int) -> np.ndarray:
    """(side, side) ranks 0 … side² − 1 of an ordered-dither (Bayer) matrix: visiting the
    cells by rank spreads every prefix over the square. Sides that are not a power of two
    take the ranks of the next power's matrix, renumbered."""
    size = 1
    ranks = np.zeros((1, 1), np.int64)
    while size < side:
        ranks = np.block([[4 * ranks, 4 * ranks + 2], [4 * ranks + 3, 4 * ranks + 1]])
        size *= 2
    ranks = ranks[:side, :side]
    return np.argsort(np.argsort(ranks.ravel())).reshape(side, side)


def sample_offset(filter_width: float, samples: int, index: int) -> tuple[float, float]:
    """Sub-pixel offset (x right, y down, pixels) of sample ``index``: the strata of a side ×
    side square (side = ⌈√samples⌉) warped by the pixel filter (``camera.filter_offsets``),
    visited in ordered-dither order (``bayer``) from a stratum next to the centre, so the
    first samples spread over the pixel. Filter Size ≤ 0: the pixel centre."""
    side = max(1, math.ceil(math.sqrt(samples)))
    offsets = filter_offsets(filter_width, side)
    ranks = np.roll(bayer(side), (max(0, side // 2 - 1),) * 2, axis=(0, 1))
    a, b = np.argwhere(ranks == index % (side * side))[0]
    x, y = offsets[a * side + b]  # offset k is stratum (k // side, k % side) in (x, y)
    return float(x), float(y)


def sample_tail_weights(filter_width: float, samples: int, index: int) -> np.ndarray:
    """(3, 3) the weights in its neighbours of sample ``index``'s offset (``sample_offset``),
    ``passes.tail_weights`` over the side × side offsets the samples visit (made once per
    sample: the viewport asks at every slice)."""
    return _sample_tail_weights(float(filter_width), int(samples), int(index)).copy()


@functools.lru_cache(maxsize=256)
def _sample_tail_weights(filter_width: float, samples: int, index: int) -> np.ndarray:
    side = max(1, math.ceil(math.sqrt(samples)))
    offsets = filter_offsets(filter_width, side)
    x, y = sample_offset(filter_width, samples, index)
    k = int(np.argmin(np.abs(offsets[:, 0] - x) + np.abs(offsets[:, 1] - y)))
    return tail_weights(offsets, filter_width)[k]


def _frustum(camera) -> tuple[float, float, float, float]:
    """(centre x, centre y, half width, half height) of the camera's image (``camera.py``)."""
    p = np.asarray(camera.projection_matrix, np.float64)
    hx, hy = 1.0 / p[0, 0], 1.0 / p[1, 1]
    if camera.type == "ORTHO":
        return -p[0, 3] * hx, -p[1, 3] * hy, hx, hy
    return p[0, 2] * hx, p[1, 2] * hy, hx, hy


def tile_camera(camera, x0: int, y0: int, width: int, height: int, offset=(0.0, 0.0)):
    """The camera of the ``width`` × ``height`` pixels of ``camera``'s image whose top-left
    pixel is (x0, y0) (row 0 on top), every ray moved by ``offset`` (x right, y down, pixels):
    pixel (i, j) of the tile is pixel (x0 + i, y0 + j) of the image, continued past its
    borders where the tile reaches beyond them. ``camera.resolution`` is the whole image's
    size (its projection's aspect)."""
    full_w, full_h = camera.resolution
    if width < 1 or height < 1 or x0 + width <= 0 or y0 + height <= 0 or x0 >= full_w \
            or y0 >= full_h:
        raise ValueError(f"tile {width}×{height} at ({x0}, {y0}) does not meet the "
                         f"{full_w}×{full_h} image")
    cx, cy, hx, hy = _frustum(camera)
    tx, ty = hx * width / full_w, hy * height / full_h
    tcx = cx + hx * (2.0 * (x0 + offset[0]) + width) / full_w - hx
    tcy = cy + hy - 2.0 * hy * (y0 + offset[1]) / full_h - ty
    p = np.array(camera.projection_matrix, np.float64)
    p[0, 0], p[1, 1] = 1.0 / tx, 1.0 / ty
    if camera.type == "ORTHO":
        p[0, 3], p[1, 3] = -tcx / tx, -tcy / ty
    else:
        p[0, 2], p[1, 2] = tcx / tx, tcy / ty
    return dataclasses.replace(camera, projection_matrix=p, resolution=(int(width), int(height)))


def inside(rect, width: int, height: int):
    """(image window, tile window): numpy slices of the part of the tile ``rect`` (x0, y0, w,
    h) inside the ``width`` × ``height`` image, in the image's and in the tile's pixels."""
    x0, y0, w, h = rect
    ix0, iy0 = max(x0, 0), max(y0, 0)
    ix1, iy1 = min(x0 + w, width), min(y0 + h, height)
    return (np.s_[iy0:iy1, ix0:ix1], np.s_[iy0 - y0:iy1 - y0, ix0 - x0:ix1 - x0])


def tile_grid(width: int, height: int, tile_w: int, tile_h: int, shift=(0, 0), trim=None):
    """[(x0, y0, w, h)] tiles covering the ``width`` × ``height`` image once each, row by row
    from the top: a grid of ``tile_w`` × ``tile_h`` tiles whose lines are moved by ``shift``
    pixels. The border tiles reach past the image (their pixels there are traced and
    dropped). trim : None, every tile that size; else ``trim(n)`` → the side a border tile
    traces for its n pixels inside the image (``fit_side``: of the kind every tile's textures
    have, since on llvmpipe a texture size of another kind — a power of two or not — compiles
    the kernels anew, seconds each), the tile reaching past the image's border alone: a tile
    of a grid moved by a fraction of a tile, or of tiles that do not divide the image, traced
    its whole size beyond the border (a 160 × 120 image in two 136 × 120 tiles traced 1.7 ×
    its pixels)."""
    tile_w, tile_h = max(1, tile_w), max(1, tile_h)
    sx, sy = shift[0] % tile_w, shift[1] % tile_h

    def spans(size, tile, start):
        out = []
        for a in range(start, size, tile):
            lo, hi = max(a, 0), min(a + tile, size)
            side = tile if trim is None else min(tile, trim(hi - lo))
            if a < 0 and hi < size:  # cut by the first border alone: it keeps its far edge
                out.append((hi - side, side))
            else:  # its near edge (inside the image unless the whole tile is untrimmed)
                out.append((a if side == tile else lo, side))
        return out

    xs = spans(width, tile_w, sx - tile_w if sx else 0)
    ys = spans(height, tile_h, sy - tile_h if sy else 0)
    return [(x0, y0, w, h) for y0, h in ys for x0, w in xs]


def sample_terms(passes, pass_name: str) -> dict[str, np.ndarray]:
    """What one sample of ``pass_name`` adds per pixel (``Accumulation.add``; the GPU's
    ``render/gpu_accumulation.py`` the same from the tracer's sums), (h, w, 3) float32 each:
    ``value`` and ``weight`` — the pass and 1, or for a light pass light × colour and the
    colour (Cycles' film divides the sums), or for Combined the pass without its gathered
    light and 1 — and ``light``, Combined's gathered light (Diffuse Color × Diffuse Indirect
    + Glossy Color × Glossy Indirect; zeros for the other passes)."""
    value = np.asarray(passes[pass_name], np.float32)
    ones = np.ones_like(value)
    if pass_name == "Combined":
        light = (np.asarray(passes["Diffuse Color"], np.float32)
                 * np.asarray(passes["Diffuse Indirect"], np.float32)
                 + np.asarray(passes["Glossy Color"], np.float32)
                 * np.asarray(passes["Glossy Indirect"], np.float32))
        return {"value": value - light, "weight": ones, "light": light}
    colour_name = LIGHT_COLOURS.get(pass_name)
    if colour_name:
        colour = np.asarray(passes[colour_name], np.float32)
        return {"value": value * colour, "weight": colour, "light": np.zeros_like(value)}
    return {"value": value, "weight": ones, "light": np.zeros_like(value)}


# a Base Color step between two pixels (linear RGB distance): above float rounding
TEXTURE_STEP = 1e-4


def texture_steps(surface, ey: int, ex: int) -> np.ndarray:
    """(h, w) bool over a tile's G-buffer ``surface`` (``Accumulation.add``'s): whether the
    pixel (y, x) and the pixel (y − ey, x − ex) of the tile both see one textured surface
    (``upsample.same_surface``; Base Color per texel, flag base[..., 3] > ½) whose Base
    Color differs between them. A view's sample takes its textures over its pixel's whole
    square whatever its sub-pixel offset (docs/gi_pipeline.md "A sample's textures over its
    pixel's square"), so across such a step its value goes into the neighbour by the filter's
    mean weight, not its offset's: the offset's weights there only swing the texture's edge
    from sample to sample (docs/gi_pipeline.md "The filter's mean across a texture's
    steps"). Elsewhere — lighting within one colour, and the geometry's edges — the offset's
    weights place what the sample saw. The GLSL port: accumulate.glsl ``texture_step``."""
    hit, material = np.asarray(surface["hit"], bool), np.asarray(surface["material"])
    position, normal = np.asarray(surface["position"]), np.asarray(surface["normal"])
    base = np.asarray(surface["base"], np.float64)
    height, width = hit.shape
    out = np.zeros((height, width), bool)
    # source (y, x) → target (y − ey, x − ex), both in the tile
    a = (slice(max(ey, 0), height + min(ey, 0)), slice(max(ex, 0), width + min(ex, 0)))
    b = (slice(max(-ey, 0), height + min(-ey, 0)), slice(max(-ex, 0), width + min(-ex, 0)))
    textured = (base[a][..., 3] > 0.5) & (base[b][..., 3] > 0.5)
    differs = np.linalg.norm(base[a][..., :3] - base[b][..., :3], axis=-1) > TEXTURE_STEP
    out[a] = hit[a] & textured & differs & same_surface(
        hit[a], material[a], position[a], normal[a], hit[b], material[b], position[b], normal[b])
    return out


class Accumulation:
    """The samples of one pass of a ``width`` × ``height`` image: per pixel the sum of the
    pass (× its colour for a light pass), of the weights (the colour, or 1) and the count.
    A gathered pass's samples (``GATHERED``) are weighted by ``add``'s ``gather_weight``;
    Combined keeps its gathered light (Diffuse Color × Diffuse Indirect + Glossy Color ×
    Glossy Indirect) apart, weighted so, and the rest with weight 1.
    film : also sum the film's (``preview.film``) world along the samples' camera rays, their
    coverage and holdout shares (``add``'s ``world``, the passes' ``Alpha`` / ``_holdout``),
    each with weight 1 and the same tails (``film_rgba``); transparent : Film › Transparent
    (alpha = coverage, no world)."""

    def __init__(self, pass_name: str, width: int, height: int, film: bool = False,
                 transparent: bool = False):
        # float32 sums: 16 bytes a pixel per buffer (a 1280 × 720 view at full resolution
        # keeps about 60 MB), exact enough for Viewport Samples' 4096 at most
        if pass_name not in PASS_NAMES:
            raise ValueError(f"unknown pass {pass_name!r}; one of {', '.join(PASS_NAMES)}")
        self.pass_name, self.width, self.height = pass_name, width, height
        self.colour_name = LIGHT_COLOURS.get(pass_name)
        self.sums = np.zeros((height, width, 3), np.float32)
        self.weights = np.zeros((height, width, 3), np.float32)
        # Combined: the gathered light's weighted sum and weights
        combined = pass_name == "Combined"
        self.gathered = np.zeros((height, width, 3), np.float32) if combined else None
        self.gather_weights = np.zeros((height, width, 1), np.float32) if combined else None
        # the colour's sum, for the filter over the neighbours (``finished``)
        self.colour = np.zeros((height, width, 3), np.float32) if self.colour_name else None
        self.counts = np.zeros((height, width), np.int32)
        # the film: world rgb, coverage, holdout; and the samples' weights (1 each)
        self.film = np.zeros((height, width, 5), np.float32) if film else None
        self.film_weights = np.zeros((height, width, 1), np.float32) if film else None
        self.transparent = bool(transparent)
        # the filter's tails: the samples' sums and weights added into the neighbours by the
        # filter at their own offsets (``add``'s tails; None until a sample brings them)
        self.tails: dict[str, np.ndarray] | None = None

    def _sums(self) -> dict[str, np.ndarray]:
        """The sums a sample adds to, by name (those the tails mirror)."""
        out = {"sums": self.sums, "weights": self.weights}
        if self.gathered is not None:
            out.update(gathered=self.gathered, gather_weights=self.gather_weights)
        if self.film is not None:
            out.update(film=self.film, film_weights=self.film_weights)
        return out

    def add(self, rect, passes, gather_weight: float = 1.0, tails=None, world=None,
            mean_tails=None, surface=None) -> None:
        """Add one sample's ``passes`` (PASS_NAMES → (h, w, 3), row 0 on top) of the tile
        ``rect`` (x0, y0, w, h); gather_weight : the weight of its gathered light. tails :
        (3, 3) the weights of the sample's offset in the neighbours (``sample_tail_weights``):
        each of its pixels' sums also goes into the 8 neighbours by them, as Cycles' film
        weighs a sample over its whole filter window (``finished``).
        world : (h, w, 3) the world along the sample's camera rays (``film.world_along``;
        None: black), for the film (an Accumulation made with ``film``).
        mean_tails : (3, 3) ``passes.neighbour_weights``, with tails and ``surface`` (the
        tile's G-buffer: hit (h, w) bool, material (h, w) int, position, normal (h, w, 3),
        base (h, w, 4) the Base Color per texel and its flag, ``gbuffer_frag.glsl``'s
        out_base): a pixel's sample goes into a neighbour of the tile by these instead of
        tails where the two see one surface (``upsample.same_surface``) whose texture differs
        between them (``texture_steps``)."""
        before = None
        if tails is not None:
            window0, _ = inside(rect, self.width, self.height)
            before = {name: array[window0].copy() for name, array in self._sums().items()}
        x0, y0, w, h = rect
        if np.shape(passes[self.pass_name])[:2] != (h, w):
            shape = np.shape(passes[self.pass_name])
            raise ValueError(f"a {shape[1]}×{shape[0]} sample for a {w}×{h} tile")
        window, part = inside(rect, self.width, self.height)
        if self.film is not None:
            if "Alpha" not in passes:
                raise ValueError("the film needs the passes' Alpha (surface coverage)")
            film = np.zeros((h, w, 5), np.float32)
            if world is not None:
                film[..., :3] = world
            film[..., 3] = passes["Alpha"]
            if "_holdout" in passes:
                film[..., 4] = passes["_holdout"]
            self.film[window] += film[part]
            self.film_weights[window] += 1.0
        terms = sample_terms(passes, self.pass_name)
        value, weights = terms["value"][part], terms["weight"][part]
        weight = gather_weight if self.pass_name in GATHERED else 1.0
        if self.gathered is not None:
            self.sums[window] += value
            self.weights[window] += weights
            self.gathered[window] += gather_weight * terms["light"][part]
            self.gather_weights[window] += gather_weight
        else:
            self.sums[window] += weight * value
            self.weights[window] += weight * weights
            if self.colour_name:
                self.colour[window] += weights
        self.counts[window] += 1
        if before is not None:
            steps = None if mean_tails is None or surface is None else \
                {key: np.asarray(array)[part] for key, array in surface.items()}
            self._add_tails(window, {name: array[window] - before[name]
                                     for name, array in self._sums().items()}, tails,
                            mean_tails, steps)

    def _add_tails(self, window, added, weights, mean=None, surface=None) -> None:
        """Add a sample's sums ``added`` (name → (h, w, C) at ``window``) into the tails of
        the pixels e before them by weights[ey + 1, ex + 1] (``passes.add_tails``); with
        ``mean`` and ``surface`` (``add``'s, over the window) by mean[ey + 1, ex + 1] where
        ``texture_steps`` holds."""
        if self.tails is None:
            self.tails = {name: np.zeros_like(array) for name, array in self._sums().items()}
        rows, cols = window
        for ey in (-1, 0, 1):
            for ex in (-1, 0, 1):
                w = float(weights[ey + 1, ex + 1])
                if (ey, ex) == (0, 0) or w == 0.0:
                    continue
                # source pixel (y, x) → target (y − ey, x − ex), inside the image
                y0, y1 = max(rows.start, ey), min(rows.stop, self.height + ey)
                x0, x1 = max(cols.start, ex), min(cols.stop, self.width + ex)
                if y0 >= y1 or x0 >= x1:
                    continue
                source = (slice(y0 - rows.start, y1 - rows.start),
                          slice(x0 - cols.start, x1 - cols.start))
                target = (slice(y0 - ey, y1 - ey), slice(x0 - ex, x1 - ex))
                factor = w
                if surface is not None:
                    step = texture_steps(surface, ey, ex)[source]
                    factor = np.where(step, float(mean[ey + 1, ex + 1]), w)[..., None]
                for name, value in added.items():
                    self.tails[name][target] += factor * value[source]

    @property
    def samples(self) -> int:
        """Samples every pixel has (the complete ones)."""
        return int(self.counts.min()) if self.counts.size else 0

    def _filtered(self, window=np.s_[:, :]) -> dict[str, np.ndarray]:
        """The sums over ``window`` with the tails the neighbours' samples brought so far
        (``add``'s), by name: each pixel's samples and its neighbours' by Cycles' pixel filter
        at their own offsets, whatever samples have landed (a weighted mean at any time)."""
        own = {name: array[window] for name, array in self._sums().items()}
        if self.tails is None:
            return own
        return {name: own[name] + self.tails[name][window] for name in own}

    def mean(self, window=np.s_[:, :]) -> np.ndarray:
        """(h, w, 3) over ``window``: the mean of the samples so far with their tails over the
        neighbours (``_filtered``; 0 where a pixel has none, or no colour)."""
        sums = self._filtered(window)
        mean = np.divide(sums["sums"], sums["weights"], out=np.zeros_like(sums["sums"]),
                         where=sums["weights"] > 0.0)
        if self.gathered is not None:
            mean += np.divide(sums["gathered"], sums["gather_weights"],
                              out=np.zeros_like(sums["gathered"]),
                              where=sums["gather_weights"] > 0.0)
        return mean

    def estimate_into(self, image, rect) -> None:
        """Refresh ``image`` ((H, W, 3), the last ``estimate``; (H, W, 4): ``estimate_rgba``'s)
        where the tile ``rect`` changed it: its pixels and, by the tails, one pixel around."""
        x0, y0, w, h = rect
        window, _ = inside((x0 - 1, y0 - 1, w + 2, h + 2), self.width, self.height)
        mean = self.mean(window)
        image[window] = mean if image.shape[2] == 3 else self.film_rgba(mean, window)

    def film_rgba(self, rgb, window=np.s_[:, :], filter_width: float | None = None):
        """(h, w, 4) float32: ``rgb`` (this pass's estimate over ``window`` of the image) on
        the film (``preview.film.film_combined``) with the samples' world, coverage and
        holdout shares there, with their tails (``_filtered``) — alpha 1 without the film.
        filter_width : the finished image's (``finished``): without tails, the shares are
        filtered over the neighbours instead."""
        rgb = np.asarray(rgb, np.float32)
        if self.film is None:
            return np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
        sums = self._filtered(window)
        film, weights = sums["film"], sums["film_weights"]
        shares = np.divide(film, weights, out=np.zeros_like(film), where=weights > 0.0)
        if filter_width is not None and self.tails is None:
            shares = filter_coverage(shares, filter_width)
        return film_combined(rgb, shares[..., 3], shares[..., :3], self.transparent,
                             shares[..., 4])

    def estimate_rgba(self, coarse=None) -> np.ndarray:
        """(H, W, 4) float32: ``estimate`` on the film (``film_rgba``); ``coarse`` (h, w, 4)
        RGBA where no sample landed yet."""
        out = self.film_rgba(self.mean())
        empty = self.counts == 0
        if coarse is not None and empty.any():
            out[empty] = scale_nearest(coarse, self.width, self.height)[empty]
        return out

    def estimate(self, coarse=None) -> np.ndarray:
        """(H, W, 3) float32: the mean (with the tails so far) where a pixel has samples,
        elsewhere ``coarse`` ((h, w, 3), any size: scaled to the image by nearest pixel), or 0
        without it."""
        out = self.mean()
        empty = self.counts == 0
        if coarse is not None and empty.any():
            out[empty] = scale_nearest(coarse, self.width, self.height)[empty]
        return out.astype(np.float32)

    def finished(self, filter_width: float) -> np.ndarray:
        """(H, W, 3) float32: the mean with Cycles' pixel filter over the neighbours, as the
        one-shot image gets it: with the samples' tails (``add``'s), ``mean`` — each pixel's
        sums and weights plus the neighbours' samples by the filter at their own offsets
        (``passes.filtered_sums``); without, the neighbours' means by their share of the
        filter (``passes.filter_passes``)."""
        if self.tails is not None:
            return self.mean().astype(np.float32)
        mean = self.mean()
        passes = {name: np.zeros_like(mean) for name in PASS_NAMES}  # not read for this pass
        passes[self.pass_name] = mean
        if self.colour_name:
            passes[self.colour_name] = self.colour / np.maximum(self.counts, 1)[..., None]
        return np.asarray(filter_passes(passes, filter_width)[self.pass_name], np.float32)


class GatherSums:
    """The samples' raw gathers (before the à-trous filter) per cell of the image's
    low-resolution gather grid (``upsample.low_shape`` at ``stride``), per kind ("diffuse",
    "glossy", "world glossy"): a tile's gather adds its cells, and the filter gets the mean
    of every sample so far — the filter runs on the accumulated rays, as on one gather of
    all of them (F12's), not on each sample's few rays.

    values (rgb, a): the mean of the samples' means. variance (the gather kernels' (var of the
    luminance mean, var of the AO mean, …)): the pooled kernel variances over n² — except the
    luminance's when a sample traces one ray (its kernel variance is 0): then the samples'
    spread, (Σ l² / n − l̄²) / (n − 1). The variance's third channel (−the points' reach in a
    gather's, ``exact_indirect.indirect_and_ao``) is 0: the view's filter bounds no tap by the
    reach, F12's does (docs/gi_pipeline.md "The filter's taps within the gather points' reach":
    the converged view lies nearer F12's image without it)."""

    def __init__(self, width: int, height: int, stride: int):
        self.width, self.height, self.stride = width, height, stride
        self.shape = low_shape(height, width, stride)
        self.kinds: dict[str, dict[str, np.ndarray]] = {}

    def add(self, kind: str, rect, values, variance, rays: int, lattice: bool = False):
        """Add one sample's raw gather of the tile ``rect`` (x0, y0, w, h; x0, y0 multiples
        of the stride; it may reach past the image): values, variance (h_l, w_l, 4), row 0 on
        top; rays : its rays per point. Returns the tile's (values, variance): over every
        sample so far in the image's cells, its own past them. rays 0 (a sample after the
        gathering ones, ``sample_settings``): nothing is added, values and variance are not
        read, and the tile's cells past the image take the nearest cell's.
        lattice : values and variance hold only the tile's lattice — its cells of odd row and
        column from its top-left, clamped to its last row and column (``lattice_cells``) — in
        the lattice's shape; the tile's other cells add nothing. A cell no sample has reached
        yet is a hole: its variance's third channel is 1 (the filter fills it)."""
        x0, y0, w, h = rect
        s = self.stride
        if x0 % s or y0 % s:
            raise ValueError(f"a tile at ({x0}, {y0}) does not start on a stride-{s} block")
        low_h, low_w = low_shape(h, w, s)
        sums = self.kinds.get(kind)
        if rays == 0:  # read only: every cell of the tile from the image's nearest cell
            if sums is None:
                raise ValueError(f"no {kind} gather was added before a sample without rays")
            rows = np.clip(np.arange(low_h) + y0 // s, 0, self.shape[0] - 1)
            cols = np.clip(np.arange(low_w) + x0 // s, 0, self.shape[1] - 1)
            mean, pooled = self._mean(sums, np.s_[rows[:, None], cols[None, :]])
            return mean.astype(np.float32), pooled.astype(np.float32)
        values = np.nan_to_num(np.asarray(values, np.float64))  # cells of no surface: unset
        variance = np.nan_to_num(np.asarray(variance, np.float64))
        given = low_shape(low_h, low_w, 2) if lattice else (low_h, low_w)
        if values.shape[:2] != given or variance.shape[:2] != given:
            raise ValueError(f"a {values.shape[1]}×{values.shape[0]} gather for a tile of "
                             f"{given[1]}×{given[0]} cells")
        added = np.ones((low_h, low_w), bool)
        if lattice:  # spread over the tile's cells, zero off the lattice
            added = lattice_cells(low_h, low_w)
            spread = [np.zeros((low_h, low_w, 4)) for _ in range(2)]
            rows, cols = np.nonzero(added)
            for out, given_cells in zip(spread, (values, variance)):
                out[rows, cols] = given_cells[rows // 2, cols // 2]
            values, variance = spread
        if sums is None:
            sums = self.kinds[kind] = {
                "values": np.zeros((*self.shape, 4)), "variance": np.zeros((*self.shape, 4)),
                "lum2": np.zeros(self.shape), "n": np.zeros(self.shape), "rays": rays}
        sums["rays"] = rays
        cells, part = inside((x0 // s, y0 // s, low_w, low_h), self.shape[1], self.shape[0])
        sums["values"][cells] += values[part]
        sums["variance"][cells] += variance[part]
        sums["lum2"][cells] += (values[part][..., :3] @ LUMINANCE) ** 2
        sums["n"][cells] += added[part]
        mean, pooled = self._mean(sums, cells)
        # the tile's cells past the image keep their own gather (off the lattice: holes)
        values, variance = values.copy(), variance.copy()
        values[part], variance[part] = mean, pooled
        variance[..., 2] = np.where(~added, 1.0, variance[..., 2])
        variance[part][..., 2] = np.where(sums["n"][cells] > 0, pooled[..., 2], 1.0)
        return values.astype(np.float32), variance.astype(np.float32)

    @staticmethod
    def _mean(sums, cells):
        """(mean, pooled variance) of the sums at ``cells`` (0 where no sample fell yet)."""
        n = sums["n"][cells][..., None]
        safe = np.maximum(n, 1.0)
        mean = sums["values"][cells] / safe
        pooled = sums["variance"][cells] / (safe * safe)
        if sums["rays"] <= 1:  # one ray a sample: its kernel variance is 0, take the spread
            count = n[..., 0]
            lum = mean[..., :3] @ LUMINANCE
            spread = np.maximum(sums["lum2"][cells] / np.maximum(count, 1.0) - lum * lum,
                                0.0) / np.maximum(count - 1.0, 1.0)
            pooled[..., 0] = np.where(count > 1.0, spread, pooled[..., 0])
        pooled[..., 2] = 0.0  # no reach (the class doc)
        return mean, pooled


# The view's first sample gathers at one cell in LATTICE_CELLS (``lattice_cells``) with
# LATTICE_RAYS × its rays, the others holes the filter fills: half its diffuse gather's rays,
# as F12's sparse gather lends the holes' rays to its traced cells (docs/gi_pipeline.md "The
# view's first sample at the lattice")
LATTICE_CELLS = 4
LATTICE_RAYS = 2


def lattice_cells(height: int, width: int) -> np.ndarray:
    """(height, width) bool: the lattice of a grid of cells — odd row, odd column from the
    top-left, and the last row and column where they are even (``upsample.sample_pixels``' at
    stride 2, read as cells): the viewport's first sample gathers at those only (``gpu_gather
    .gather_steps``' lattice), cell (i, j) of the lattice's own grid at (2 i + 1, 2 j + 1)."""
    rows = np.minimum(np.arange(-(-height // 2)) * 2 + 1, height - 1)
    cols = np.minimum(np.arange(-(-width // 2)) * 2 + 1, width - 1)
    cells = np.zeros((height, width), bool)
    cells[rows[:, None], cols[None, :]] = True
    return cells


def scale_nearest(image, width: int, height: int) -> np.ndarray:
    """``image`` (h, w, C) scaled to ``width`` × ``height`` by nearest pixel."""
    image = np.asarray(image)
    h, w = image.shape[:2]
    rows = np.minimum((np.arange(height) + 0.5) * h / height, h - 1).astype(int)
    cols = np.minimum((np.arange(width) + 0.5) * w / width, w - 1).astype(int)
    return image[rows][:, cols]


class SliceSizer:
    """Pixels per slice for a time budget, from measured slices: seconds ≈ fixed + per_pixel ×
    pixels, fitted robustly (Theil–Sen: the median slope between slices of different sizes,
    then the median intercept) over the last ``keep`` slices, so a slice that waited for a
    kernel compile or another process does not skew it. The budget is met by the slices'
    ``TAIL`` quantile, not their median: the model is scaled by that quantile of the measured
    over the modelled seconds (at least 1), so a machine whose slices scatter (another process,
    the worker thread's Python) gets smaller ones. Until there is a measurement:
    ``first_pixels``; while the measured slices have one size, twice that (the fit needs two),
    and after a fit the last fit. When the recent slices have one size (the image's tiles all
    alike), every ``explore``-th call asks another: half the fitted size, which stays within
    the budget, or, where the smallest tile holds every slice, 2 × the last measured size, so
    the fit follows a machine whose load changes there too. A slice never has fewer pixels
    than its fixed cost is worth (fixed / per_pixel: at least half of it tracing), so where the
    fixed cost alone is over the budget (a slow or loaded machine) slices run over it rather
    than spend most of their time on overhead — unless ``amortize`` is False (the viewport's
    staged slices, sized by their longest stage: a bigger slice would only make that stage
    longer), where such a machine gets ``least``."""

    def __init__(self, budget: float, first_pixels: int = 4096, least: int = 256,
                 keep: int = 48, explore: int = 4, amortize: bool = True):
        if budget <= 0.0:
            raise ValueError(f"the slice budget must be positive, not {budget}")
        self.budget, self.first_pixels, self.least, self.keep = budget, first_pixels, least, keep
        self.explore, self.amortize = explore, amortize
        self.samples: list[tuple[int, float]] = []
        self.fitted: tuple[float, float] | None = None  # the last fit from two sizes
        self.calls = 0

    def measured(self, pixels: int, seconds: float) -> None:
        self.samples = [*self.samples, (int(pixels), float(seconds))][-self.keep:]

    def _sized(self) -> bool:
        """Whether the kept slices have sizes far enough apart to fit a slope."""
        p = [s[0] for s in self.samples]
        return len(p) >= 2 and max(p) - min(p) > 0.25 * sum(p) / len(p)

    def model(self) -> tuple[float, float] | None:
        """(fixed seconds, seconds per pixel), or None until two sizes were measured; while
        the recent slices have one size, the last fit from two."""
        if not self._sized():
            return self.fitted
        p = np.array([s[0] for s in self.samples], np.float64)
        t = np.array([s[1] for s in self.samples], np.float64)
        i, j = np.triu_indices(len(p), 1)
        apart = np.abs(p[i] - p[j]) > 0.25 * p.mean()
        slope = float(np.median((t[i] - t[j])[apart] / (p[i] - p[j])[apart]))
        if slope <= 0.0:  # noise swamped the sizes' difference: all of it per pixel
            self.fitted = 0.0, float(np.median(t / p))
        else:
            self.fitted = max(float(np.median(t - slope * p)), 0.0), slope
        return self.fitted

    def tail(self, fitted: tuple[float, float] | None = None) -> float:
        """How much longer than the model the ``TAIL`` quantile of the kept slices ran (at
        least 1): what the budget is divided by. 1 until ``TAIL_LEAST`` slices were measured
        (the quantile of a few is their longest); a slice more than ``ONE_OFF`` times its
        model's median ratio waited for something once (a kernel's build, another process's
        burst), which no size would have kept within the budget: it is left out. But when the
        last ``RECENT`` slices all ran slower than that quantile says, the least of their
        ratios is taken: the machine is slower now (a burst of another process), and the next
        slices are sized for it until a slice runs at its usual pace. fitted : the
        ``model()`` the caller has already fitted (None: fitted here)."""
        fitted = self.model() if fitted is None else fitted
        if fitted is None or len(self.samples) < TAIL_LEAST:
            return 1.0
        fixed, per_pixel = fitted
        p = np.array([s[0] for s in self.samples], np.float64)
        t = np.array([s[1] for s in self.samples], np.float64)
        ratio = t / np.maximum(fixed + per_pixel * p, 1e-9)
        recent = float(ratio[-RECENT:].min())  # (a burst: every one of them slow)
        ratio = ratio[ratio <= ONE_OFF * np.median(ratio)]
        return max(1.0, float(np.quantile(ratio, TAIL)), recent)

    def pixels(self, most: int, explore: bool = True) -> int:
        """Pixels of the next slice, between ``least`` and ``most``. explore False: the fitted
        size only, never another one to measure (a slice the view waits for: the coarse
        first image)."""
        fitted = self.model()
        if explore:
            self.calls += 1
        if fitted is None:
            pixels = 2 * self.samples[-1][0] if self.samples and explore else self.first_pixels
        else:
            fixed, per_pixel = fitted
            budget = self.budget / self.tail(fitted)
            spare = max(budget - fixed, fixed if self.amortize else 0.0)
            pixels = spare / per_pixel
            if explore and self.explore and self.calls % self.explore == 0 and \
                    not self._sized():  # another size, for the fit
                pixels = (0.5 * pixels if pixels >= 2 * self.least else
                          2.0 * max(pixels, self.samples[-1][0] if self.samples else 0))
        return int(max(min(self.least, most), min(most, pixels)))


def allowed_side(side: int, stride: int) -> bool:
    """A tile side whose textures are of every tile's kind: no power of two, in pixels nor in
    gather cells (pixels / stride)."""
    cells = side // stride
    return side & (side - 1) != 0 and cells & (cells - 1) != 0


def tile_side(target: float, multiple: int, stride: int) -> int:
    """The allowed tile side nearest ``target`` (at least the smallest): a multiple of
    ``multiple`` that is no power of two, in pixels nor in gather cells (pixels / stride), so
    every tile's textures are of one kind (llvmpipe compiles a kernel variant per
    power-of-two-ness of its textures' sizes: 5–20 s each for the BVH kernels under load)."""
    sides = [k * multiple for k in range(1, max(4, int(target // multiple) + 3))
             if allowed_side(k * multiple, stride)]
    return min(sides, key=lambda side: (abs(side - target), side))


def fit_side(pixels: int, multiple: int, stride: int) -> int:
    """The least allowed tile side (``tile_side``'s kind) holding ``pixels`` pixels: what a
    tile cut by the image's border traces (``tile_grid``'s trim)."""
    side = max(multiple, -(-pixels // multiple) * multiple)
    while not allowed_side(side, stride):
        side += multiple
    return side


def tile_shape(pixels: int, width: int, height: int, multiple: int = 1,
               stride: int = 1) -> tuple[int, int]:
    """(tile width, tile height) of about ``pixels`` pixels (``tile_side``: square-ish, sides
    multiples of ``multiple`` — whole work groups of the gather grid — of one texture kind);
    the whole image when it has no more than ``pixels``."""
    if pixels >= width * height:
        return width, height
    tile_w = tile_side(min(math.sqrt(max(pixels, 1)), width + multiple - 1), multiple, stride)
    tile_h = tile_side(min(pixels / tile_w, height + multiple - 1), multiple, stride)
    return tile_w, tile_h

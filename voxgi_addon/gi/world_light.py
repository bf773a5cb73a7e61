"""The world (uniform colour, HDRI, sky: any ``WorldData.radiance`` map) as a light.

Cycles lights a surface point p (normal n) from the world with
``∫ L(ω) V(p, ω) max(n·ω, 0) / π dω`` in its Diffuse Direct pass (irradiance / π, no albedo),
the world seen straight from the surface being direct light. VoxGI evaluates it as the area
lights are (``direct_light``): the unshadowed value exactly, times the visible share estimated
with shadow rays.

* **Unshadowed**, ``E(n)/π``: a table of the map's cosine convolution over a grid of normals
  (``IRRADIANCE_HEIGHT`` rows from the zenith to the nadir *inclusive*, so that the poles —
  every floor and ceiling — are exact, × 2·that columns at the map's azimuths), from the map
  box-averaged to ``SOURCE_HEIGHT`` rows (smaller maps repeat their pixels up to it), read
  bilinearly (``unshadowed``). No noise; the cosine lobe is so wide that the grid's
  interpolation error stays below 0.2 % of the peak.
* **Visible share**, per colour channel: a ratio estimator ``Σ f V / Σ f`` over the shadow
  rays, f = L(ω) max(n·ω, 0) / (p_map(ω) + p_cos(ω)) — each of the m × m strata of the point's
  hashed stream (``sampling.hashed_square``, stream = the world's index after the lamps) gives
  one direction drawn by the map's importance (p_map ∝ luminance, a 2D CDF over rows and
  columns, uniform in solid angle inside a pixel) and one cosine-distributed about n; with
  both techniques in every stratum, the balance heuristic of multiple importance sampling is
  that sum. A small bright sun in an HDRI gets nearly every map sample (sharp, noise-free
  shadows), a uniform sky the cosine samples. Where every ray is unoccluded the share is
  exactly 1.
* **The sun apart** at a pixel's strata: a map whose few brightest pixels carry most of its
  light (``Sun``) has them traced as a lamp is — one ray a stratum by the sun's own power, the
  four corner strata first and the rest only where those disagree (a penumbra) — while the
  map's and the cosine's rays leave them out (``_sun_hidden``).

``WorldLight`` holds the tables (built once per world content, ``world_light``) and stands in
the lights list beside ``LightData`` lamps with ``type == "WORLD"``; ``world_table`` packs it
into one RGBA32F texture for ``render/shaders/bvh_lights.glsl``, which draws the same samples.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene.equirect import box_downsample, direction_to_pixel, pixel_directions, row_solid_angles
from ..scene.short_axis import any_along, norm3
from .sampling import perpendicular_basis

__all__ = ["WorldLight", "world_light", "scene_lights", "sun_lamp", "sun_shadow", "world_direct", "world_table",
           "one_technique", "sample_world", "sample_sun", "world_pdf", "world_radiance",
           "IRRADIANCE_HEIGHT", "SOURCE_HEIGHT"]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
IRRADIANCE_HEIGHT = 32   # rows of the unshadowed-irradiance table (columns: twice that)
SOURCE_HEIGHT = 128      # rows of the map the irradiance table is integrated from
# normals of the table integrated at once: their cosines to every box of the map (128 × 256) stay
# under numpy's 4 MiB threshold for transparent huge pages, whose first faults stalled a new
# process's first table 1.2–2.9 s (docs/gi_pipeline.md "The world's table without huge pages")
_NORMALS_AT_ONCE = 12
_CACHE_SIZE = 4
# The sun of a map: its pixels brighter than SUN_CONTRAST × the map's mean luminance (at most
# SUN_PIXELS, the brightest), kept apart when they carry at least SUN_SHARE of its luminous
# power — a pixel's strata (its centre's, its sub-pixel samples') then trace it as a lamp is
# traced (the four corner strata first, all only where they disagree) and the rest of the
# map without it (``Sun``;
# docs/gi_pipeline.md "The sun of an HDRI traced as a lamp"). SUN_SHARE: the corners' four
# rays cost less than the map rays the sun takes off the sky's sixteen (share × 16 ≥ 4).
SUN_CONTRAST = 100.0
SUN_PIXELS = 256
SUN_SHARE = 0.25


@dataclass(frozen=True, eq=False)
class Sun:
    """A map's sun: its K pixels row by row, the rows' inclusive CDF of their power (per
    pixel, its row's value) and each pixel's inclusive CDF within its row, all rounded to
    float32 as the GPU's table holds them; ``threshold`` the luminance above which a pixel is
    the sun's (half-way between the sun's dimmest pixel and the brightest other one) and
    ``total`` its luminous power Σ lum(L) ω (the sun's pdf is lum(L) / total)."""

    rows: np.ndarray
    columns: np.ndarray
    row_cdf: np.ndarray
    column_cdf: np.ndarray
    threshold: float
    total: float


@dataclass(frozen=True, eq=False)
class WorldLight:
    """The world as a light: its map and the tables to sample and integrate it.

    radiance : (H, W, 3) float64 (Cycles' units; ``WorldData.radiance``).
    row_cdf : (H,) inclusive CDF over rows of the pixels' power (luminance × solid angle).
    column_cdf : (H, W) inclusive CDF over each row's columns (rows of no power: uniform).
    total : Σ luminance × solid angle (the normaliser of the map's pdf).
    irradiance : (IRRADIANCE_HEIGHT, 2 · IRRADIANCE_HEIGHT, 3) float64, E(n)/π at the normal
        of each pixel centre.
    """

    key: str
    radiance: np.ndarray
    row_cdf: np.ndarray
    column_cdf: np.ndarray
    total: float
    irradiance: np.ndarray
    sun: Sun | None = None
    type: str = "WORLD"
    name: str = "World"

    @property
    def uniform(self) -> bool:
        """One radiance everywhere (a plain Background colour): the cosine rays alone are the
        exact importance of its light, so the map's rays are left out."""
        return bool(np.all(self.radiance == self.radiance[0, 0]))

    @property
    def rest_share(self) -> float:
        """The share of the map's luminous power outside its ``Sun`` (1 without one): the
        light its map and cosine rays estimate at a point the sun's rays are traced apart at."""
        return 1.0 if self.sun is None else max(0.0, 1.0 - self.sun.total / self.total)


def _table_normals() -> np.ndarray:
    """(IRRADIANCE_HEIGHT, 2 · that, 3) the normals of the irradiance table: row i at elevation
    π/2 − i·π/(IRRADIANCE_HEIGHT − 1), column j at the map convention's azimuth."""
    ih = IRRADIANCE_HEIGHT
    el = np.pi / 2 - np.arange(ih) * np.pi / (ih - 1)
    phi = -np.pi + (np.arange(2 * ih) + 0.5) * np.pi / ih
    return np.stack([np.cos(el)[:, None] * np.cos(phi)[None], np.cos(el)[:, None] * np.sin(phi)[None],
                     np.broadcast_to(np.sin(el)[:, None], (ih, 2 * ih))], axis=-1)


def _irradiance_table(radiance: np.ndarray) -> np.ndarray:
    """(IRRADIANCE_HEIGHT, 2 · that, 3) unshadowed irradiance / π of the map at the table's
    normals. A uniform map's is its radiance at every normal (∫ L max(0, n·ω) dω = πL),
    exactly and at once: the quadrature took 0.35–0.9 s of a plain Background colour's first
    image in the viewport (docs/gi_pipeline.md "Entering Rendered mode").

    Otherwise a quadrature over the map in boxes of SOURCE_HEIGHT rows: each box its power
    (Σ L ω over its pixels) from its luminance's centroid, the mean of its pixels' directions
    weighted by their luminous power. A sun a few pixels wide then lights the table from
    where it is, not from its box's centre: a sun 2.6° above the horizon read from the centre
    of its 1.4° box lit the ground 5% too dark (docs/gi_pipeline.md "The world's irradiance
    from where its light is")."""
    if np.all(radiance == radiance[0, 0]):
        return np.broadcast_to(np.asarray(radiance[0, 0], np.float64),
                               (IRRADIANCE_HEIGHT, 2 * IRRADIANCE_HEIGHT, 3)).copy()
    if len(radiance) < SOURCE_HEIGHT:  # finer quadrature over the same constant pixels
        k = -(-SOURCE_HEIGHT // len(radiance))
        radiance = np.repeat(np.repeat(radiance, k, axis=0), k, axis=1)
    height, width = radiance.shape[:2]
    power = np.asarray(radiance, np.float32) * \
        row_solid_angles(height, width).astype(np.float32)[:, None, None]  # L ω per pixel
    # the luminous power's first moment over the pixel centres (equirect.pixel_directions'
    # (cos el cos φ, cos el sin φ, sin el), built from its separable factors in float32)
    el = np.pi / 2 - (np.arange(height) + 0.5) * np.pi / height
    phi = -np.pi + (np.arange(width) + 0.5) * 2 * np.pi / width
    luminous = power @ LUMINANCE.astype(np.float32)
    pull = np.empty((height, width, 3), np.float32)
    np.multiply(luminous * np.cos(el).astype(np.float32)[:, None],
                np.cos(phi).astype(np.float32)[None], out=pull[..., 0])
    np.multiply(luminous * np.cos(el).astype(np.float32)[:, None],
                np.sin(phi).astype(np.float32)[None], out=pull[..., 1])
    np.multiply(luminous, np.sin(el).astype(np.float32)[:, None], out=pull[..., 2])
    boxes = box_downsample(power, SOURCE_HEIGHT).astype(np.float64)
    moment = box_downsample(pull, SOURCE_HEIGHT).astype(np.float64)
    total = power.sum(axis=(0, 1), dtype=np.float64)
    box_sum = boxes.sum(axis=(0, 1))
    weighted = boxes * np.divide(total, box_sum, out=np.zeros(3), where=box_sum > 0)
    h, w = boxes.shape[:2]
    length = np.linalg.norm(moment, axis=-1, keepdims=True)
    dirs = np.where(length > 0, moment / np.maximum(length, 1e-300),
                    pixel_directions(h, w)).reshape(-1, 3)
    weighted = weighted.reshape(-1, 3) / math.pi
    normals = _table_normals().reshape(-1, 3)
    out = np.zeros((len(normals), 3))
    across = np.ascontiguousarray(dirs.T)
    for a in range(0, len(normals), _NORMALS_AT_ONCE):
        cos = normals[a:a + _NORMALS_AT_ONCE] @ across
        np.maximum(cos, 0.0, out=cos)
        out[a:a + _NORMALS_AT_ONCE] = cos @ weighted
    return out.reshape(IRRADIANCE_HEIGHT, 2 * IRRADIANCE_HEIGHT, 3)


def build_world_light(radiance, key: str = "") -> WorldLight | None:
    """The ``WorldLight`` of an (H, W, 3) map; None for a map with no light (black, or only
    non-finite/negative values, which count as 0)."""
    radiance = np.nan_to_num(np.asarray(radiance, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    # float32 values, as the GPU table holds them: both tracers then take the same branches
    radiance = np.maximum(radiance, 0.0).astype(np.float32).astype(np.float64)
    h, w = radiance.shape[:2]
    power = (radiance @ LUMINANCE) * row_solid_angles(h, w)[:, None]
    total = float(power.sum())
    if not total > 0:
        return None
    rows = power.sum(axis=1)
    row_cdf = np.cumsum(rows) / total
    row_cdf[-1] = 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        column_cdf = np.cumsum(power, axis=1) / rows[:, None]
    empty = ~(rows > 0)
    column_cdf[empty] = (np.arange(1, w + 1) / w)[None]
    column_cdf[:, -1] = 1.0
    row_cdf, column_cdf = (a.astype(np.float32).astype(np.float64) for a in (row_cdf, column_cdf))
    total = float(np.float32(total))
    irradiance = _irradiance_table(radiance).astype(np.float32).astype(np.float64)
    return WorldLight(key, radiance, row_cdf, column_cdf, total, irradiance,
                      _find_sun(radiance, power, total))


def _find_sun(radiance, power, total: float) -> Sun | None:
    """The ``Sun`` of a map (its luminous ``power`` per pixel, ``total`` its sum), or None:
    the pixels brighter than SUN_CONTRAST × the mean luminance (the SUN_PIXELS brightest),
    when they carry SUN_SHARE of the power."""
    flat = (radiance @ LUMINANCE).reshape(-1)
    bright = flat > SUN_CONTRAST * total / (4 * math.pi)
    candidates = np.flatnonzero(bright)
    if len(candidates) == 0:
        return None
    order = candidates[np.argsort(flat[candidates], kind="stable")[::-1]]
    inside = order[:SUN_PIXELS]
    # the brightest pixel left out: the next candidate, or the brightest of the others
    outside = flat[order[SUN_PIXELS]] if len(order) > SUN_PIXELS else \
        float(np.max(np.where(bright, 0.0, flat)))
    dimmest = float(flat[inside].min())
    if not dimmest > outside:  # a tie at the cut: the pixels of that luminance are left out
        inside = inside[flat[inside] > outside]
        if len(inside) == 0:
            return None
        dimmest = float(flat[inside].min())
    sun_power = power.reshape(-1)[inside]
    share = float(sun_power.sum()) / total
    if share < SUN_SHARE:
        return None
    width = radiance.shape[1]
    rows, columns = np.divmod(np.sort(inside), width)
    each = power[rows, columns]
    sun_total = float(each.sum())
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    row_power = np.add.reduceat(each, starts)
    row_of = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(rows)]))
    row_cdf = (np.cumsum(row_power) / sun_total)[row_of]
    row_cdf[row_of == len(starts) - 1] = 1.0
    within = np.cumsum(each) - np.repeat(np.r_[0.0, np.cumsum(row_power)[:-1]],
                                         np.diff(np.r_[starts, len(rows)]))
    column_cdf = within / np.repeat(row_power, np.diff(np.r_[starts, len(rows)]))
    ends = np.r_[starts[1:], len(rows)] - 1
    column_cdf[ends] = 1.0
    threshold = float(np.float32(0.5 * (dimmest + outside)))
    return Sun(rows, columns, row_cdf.astype(np.float32).astype(np.float64),
               column_cdf.astype(np.float32).astype(np.float64), threshold,
               float(np.float32(sun_total)))


_cache: dict[str, tuple[tuple, WorldLight | None]] = {}


def _fingerprint(radiance) -> tuple:
    """A cheap check that a cached key still names the same map: its shape and a strided
    sample of at most 4096 of its values."""
    flat = np.asarray(radiance).reshape(-1)
    step = max(1, len(flat) // 4096)
    return radiance.shape, flat[::step].tobytes()


def world_light(world) -> WorldLight | None:
    """The ``WorldLight`` of a ``WorldData`` (None: a black world), cached by its ``key`` (a
    content key; a map that no longer matches the cached one's fingerprint is built anew, so a
    reused key cannot hand back another world's light)."""
    radiance = getattr(world, "radiance", None)
    if radiance is None:
        return None
    key = getattr(world, "key", "") or ""
    fingerprint = _fingerprint(radiance) if key else None
    if key and key in _cache and _cache[key][0] == fingerprint:
        return _cache[key][1]
    light = build_world_light(radiance, key)
    if key:
        _cache.pop(key, None)
        while len(_cache) >= _CACHE_SIZE:
            _cache.pop(next(iter(_cache)))
        _cache[key] = (fingerprint, light)
    return light


def sun_lamp(world: WorldLight | None):
    """The map's ``Sun`` as a sun lamp (``LightData``, type SUN) for the glossy light a pixel's
    lobe takes of it (docs/gi_pipeline.md "An HDRI's sun in a glossy lobe"), or None: its
    direction the luminous-power-weighted mean of its pixels' directions, its disc the larger
    of the one of their solid angle and the one whose spread (√2 × the power-weighted RMS
    angle from that direction, a uniform disc's radius) they show, its irradiance at normal
    incidence Σ L ω over them (per channel: Strength 1 × that colour)."""
    from ..scene.snapshot import LightData

    if world is None or world.sun is None:
        return None
    sun = world.sun
    h, w = world.radiance.shape[:2]
    radiance = world.radiance[sun.rows, sun.columns]
    omega = row_solid_angles(h, w)[sun.rows]
    dirs = pixel_directions(h, w)[sun.rows, sun.columns]
    luminous = (radiance @ LUMINANCE) * omega
    middle = (dirs * luminous[:, None]).sum(axis=0)
    middle /= max(float(np.linalg.norm(middle)), 1e-300)
    angles = np.arccos(np.clip(dirs @ middle, -1.0, 1.0))
    spread = math.sqrt(2.0 * float((luminous * angles ** 2).sum() / luminous.sum()))
    covered = math.acos(max(-1.0, 1.0 - float(omega.sum()) / (2.0 * math.pi)))
    radius = min(max(spread, covered), 0.5 * math.pi)
    matrix = np.eye(4)
    matrix[:3, :3] = _frame_along(-middle)
    colour = (radiance * omega[:, None]).sum(axis=0)
    return LightData(name="World Sun", type="SUN", color=colour.astype(np.float32), power=1.0,
                     world_matrix=matrix, angle=2.0 * radius)


def sun_shadow(sun):
    """``sun_lamp``'s lamp as its shadow rays see it: one ray toward its middle (no angle). Its
    glossy light needs its visible share, not its penumbra, which the world's own rays trace
    for its Diffuse Direct: four and more rays a pixel over its disc cost the HDRI courtyard at
    640 × 480 0.3 s (10%) for the same image. None for None."""
    from dataclasses import replace

    return None if sun is None else replace(sun, angle=0.0)


def _frame_along(direction) -> np.ndarray:
    """(3, 3) a rotation whose local −Z is the unit ``direction`` (a lamp shines along its −Z)."""
    z = -np.asarray(direction, np.float64)
    x, y = perpendicular_basis(z[None])
    return np.stack([x[0], y[0], z], axis=1)


def scene_lights(snapshot, tris=None, emission=None) -> list:
    """The snapshot's lamps, then its world when it sheds light (``WorldLight``), then, given
    its triangles (``SceneTriangles``) and the materials' emission (``preview.passes
    .material_table``), its emissive triangles (``emitters.EmitterLight``)."""
    from .emitters import emitter_light

    world = world_light(snapshot.world)
    lights = list(snapshot.lights) + ([world] if world is not None else [])
    emitters = None if tris is None else emitter_light(tris, emission)
    return lights + ([emitters] if emitters is not None else [])


def _pixel_of(world: WorldLight, directions):
    h, w = world.radiance.shape[:2]
    rows, cols = direction_to_pixel(directions, h, w)
    i = np.clip(np.floor(rows).astype(np.int64), 0, h - 1)
    j = np.floor(cols).astype(np.int64) % w
    return i, j


def world_radiance(world: WorldLight, directions) -> np.ndarray:
    """(..., 3) radiance of the map's pixel holding each unit direction (..., 3) (nearest, as
    its pdf is piecewise constant)."""
    i, j = _pixel_of(world, directions)
    return world.radiance[i, j]


def world_pdf(world: WorldLight, directions) -> np.ndarray:
    """Solid-angle pdf of ``sample_world`` in unit ``directions`` (..., 3)."""
    i, j = _pixel_of(world, directions)
    return world.radiance[i, j] @ LUMINANCE / world.total


def sample_world(world: WorldLight, square) -> np.ndarray:
    """Unit directions (..., 3) drawn by the map's importance from ``square`` (..., 2) in
    [0, 1)²: the row from the first coordinate, the column from the second (inverse CDFs),
    then uniform in solid angle (in z = sin el and in azimuth) inside the pixel, with the
    coordinates' remainders."""
    h, w = world.radiance.shape[:2]
    u = np.asarray(square, np.float64)
    u0, u1 = u[..., 0], u[..., 1]
    i = np.minimum(np.searchsorted(world.row_cdf, u0, side="right"), h - 1)
    low = np.where(i > 0, world.row_cdf[np.maximum(i - 1, 0)], 0.0)
    f0 = np.clip((u0 - low) / np.maximum(world.row_cdf[i] - low, 1e-30), 0.0, 1.0)
    cdf = world.column_cdf[i]  # (..., W)
    j = np.minimum((cdf <= u1[..., None]).sum(axis=-1), w - 1)
    left = np.where(j > 0, np.take_along_axis(cdf, np.maximum(j - 1, 0)[..., None], -1)[..., 0], 0.0)
    right = np.take_along_axis(cdf, j[..., None], -1)[..., 0]
    f1 = np.clip((u1 - left) / np.maximum(right - left, 1e-30), 0.0, 1.0)
    return _inside_pixel(i, j, f0, f1, h, w)


def sample_sun(world: WorldLight, square) -> np.ndarray:
    """Unit directions (..., 3) drawn by the luminous power of the map's sun (``Sun``) from
    ``square`` (..., 2): the row by the first coordinate, the pixel in it by the second, then
    uniform in solid angle inside the pixel with their remainders (as ``sample_world``; GLSL
    ``world_sun_sample``). Its pdf is lum(L) / ``Sun.total``."""
    sun = world.sun
    h, w = world.radiance.shape[:2]
    u = np.asarray(square, np.float64)
    u0, u1 = u[..., 0], u[..., 1]
    last = len(sun.rows) - 1
    first = np.minimum(np.searchsorted(sun.row_cdf, u0, side="right"), last)
    low = np.where(first > 0, sun.row_cdf[np.maximum(first - 1, 0)], 0.0)
    high = sun.row_cdf[first]
    f0 = np.clip((u0 - low) / np.maximum(high - low, 1e-30), 0.0, 1.0)
    end = np.searchsorted(sun.row_cdf, high, side="right")  # the row is [first, end)
    # the pixel: the first of the row whose CDF exceeds u1 (a binary search within the row)
    pixel = first.copy()
    for step in _halvings(last + 1):
        probe = pixel + step
        ok = (probe < end) & (sun.column_cdf[np.minimum(probe - 1, last)] <= u1)
        pixel = np.where(ok, probe, pixel)
    pixel = np.minimum(pixel, end - 1)
    left = np.where(pixel > first, sun.column_cdf[np.maximum(pixel - 1, 0)], 0.0)
    right = sun.column_cdf[pixel]
    f1 = np.clip((u1 - left) / np.maximum(right - left, 1e-30), 0.0, 1.0)
    i, j = sun.rows[pixel], sun.columns[pixel]
    return _inside_pixel(i, j, f0, f1, h, w)


def _inside_pixel(i, j, f0, f1, h: int, w: int) -> np.ndarray:
    """Unit directions in pixels (i, j) of an h × w map at fractions (f0, f1) of the pixel: in
    z = sin el by f0 and in azimuth by f1, so uniform in solid angle inside it."""
    z_top = np.cos(i * math.pi / h)
    z_bottom = np.cos((i + 1) * math.pi / h)
    z = z_top + f0 * (z_bottom - z_top)
    phi = -math.pi + (j + f1) * (2 * math.pi / w)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _halvings(count: int):
    """The steps of a binary search over ``count`` items: the largest power of two below it,
    halved down to 1."""
    step = 1 << max(0, (count - 1).bit_length() - 1)
    while step >= 1:
        yield step
        step >>= 1


def _cosine(normals, square):
    """Cosine-distributed unit directions about unit normals (N, 3) from square (N, K, 2)."""
    from .direct_light import concentric_disk

    disk = concentric_disk(square)
    lift = np.sqrt(np.maximum(0.0, 1.0 - (disk ** 2).sum(-1)))
    t, b = perpendicular_basis(normals)
    d = disk[..., :1] * t[:, None] + disk[..., 1:] * b[:, None] + lift[..., None] * normals[:, None]
    return d / norm3(d)[..., None]


def unshadowed(world: WorldLight, normals) -> np.ndarray:
    """(N, 3) E(n)/π of the whole map at unit ``normals``: the table read bilinearly, rows in
    elevation (poles included), columns wrapping in azimuth (``bvh_lights.glsl``
    world_unshadowed does the same in float32)."""
    n = np.asarray(normals, np.float64)
    ih = IRRADIANCE_HEIGHT
    iw = 2 * ih
    el = np.arcsin(np.clip(n[..., 2], -1.0, 1.0))
    phi = np.where((n[..., 0] == 0) & (n[..., 1] == 0), 0.0, np.arctan2(n[..., 1], n[..., 0]))
    y = np.clip((np.pi / 2 - el) * (ih - 1) / np.pi, 0.0, ih - 1.0)
    x = (phi + np.pi) * iw / (2 * np.pi) - 0.5
    y0 = np.minimum(np.floor(y).astype(np.int64), ih - 2)
    fy = (y - y0)[..., None]
    x0f = np.floor(x)
    fx = (x - x0f)[..., None]
    x0 = x0f.astype(np.int64) % iw
    x1 = (x0 + 1) % iw
    table = world.irradiance
    top = table[y0, x0] * (1 - fx) + table[y0, x1] * fx
    bottom = table[y0 + 1, x0] * (1 - fx) + table[y0 + 1, x1] * fx
    return top * (1 - fy) + bottom * fy


# From this many strata a light's shadowed value is held at 0 or above (``hidden_less``);
# below, the estimate may dip under 0, as a single shadow ray's must to stay unbiased.
DIFFERENCE_STRATA = 4


def hidden_less(value, f, blocked, strata: int, held: bool | None = None) -> np.ndarray:
    """(N, 3) a light's shadowed value from its exact unshadowed ``value`` (N, 3) and its
    rays' ``f`` (N, R, 3) = L cos / pdf (per stratum and technique) and ``blocked`` (N, R): the
    value less the hidden rays' Σ f / (strata π) — exact where no ray is hidden, unbiased
    where some are (the visible share Σ seen f / Σ f it replaces is a ratio of two estimates,
    biased there: docs/gi_pipeline.md "The world's light where it is partly hidden"). Held at
    0 from DIFFERENCE_STRATA strata (a pixel's light); a bounce hit's or a probe ray's single
    stratum is not held — the mean over the many rays that read it is what counts, and held at
    0 a mostly hidden world read bright there (a probe's dim side 0.30 off Cycles). held :
    hold it at 0 whatever the strata (a pixel's light that is never a bounce hit's: the
    emitters' exact estimate)."""
    light = value - (f * blocked[..., None]).sum(axis=1) / (strata * math.pi)
    held = strata >= DIFFERENCE_STRATA if held is None else held
    return np.maximum(light, 0.0) if held else light


def hidden_variance(f, blocked, strata: int) -> np.ndarray:
    """(N,) the variance of the luminance of ``hidden_less``' estimate of the hidden part,
    Σ h / strata over the R rays of ``f`` (N, R, 3), h = lum(f) / π where ``blocked``:
    R / strata² × the rays' sample variance of h, the rays taken as independent (an upper bound
    under the strata; GLSL ``world_variance``, bvh_lights.glsl)."""
    h = np.where(blocked, (np.asarray(f, np.float64) @ LUMINANCE) / math.pi, 0.0)
    rays = h.shape[1]
    spread = np.maximum((h * h).sum(axis=1) - h.sum(axis=1) ** 2 / rays, 0.0) / max(rays - 1, 1)
    return rays / strata * spread / strata


def one_technique(square):
    """(mapped (M, K) bool, the strata (M, K, 2) for the drawn technique's direction): each
    stratum draws one direction, by the world map's importance where its first coordinate is
    under ½, else by the cosine, that coordinate stretched back over [0, 1) — one-sample
    multiple importance sampling, each ray weighed by L cos over the techniques' mean density
    (½ (p_map + p_cos)): unbiased, at one shadow ray a stratum instead of two
    (bvh_lights.glsl world_direct_lobe's ``single``; docs/gi_pipeline.md "One world ray a
    bounce hit")."""
    square = np.asarray(square, np.float64)
    u = square[..., 0]
    mapped = u < 0.5
    drawn = square.copy()
    drawn[..., 0] = np.where(mapped, 2.0 * u, 2.0 * u - 1.0)
    return mapped, drawn


def world_direct(world: WorldLight, p, n, occluded, strata, reflect=None, sampled=None,
                 variance=None, single: bool = False, held: bool | None = None, rest=None,
                 fewer=None):
    """(N, 3) Diffuse Direct of the world at points p with unit normals n (facing the viewer):
    the unshadowed table value less the estimate of its hidden part from one world-map and one
    cosine ray per stratum (the balance heuristic; ``hidden_less``).

    occluded : callable(origins (M, 3), unit directions (M, 3)) -> (M,) bool, the shadow test
        of rays to infinity (None: no shadows); strata : callable(point indices) -> (N, K, 2)
        the points' hashed strata.
    reflect : callable(point indices (M,), unit directions (M, K, 3)) -> (M, K, 3), a BSDF ×
        cos toward the light (a bounce hit's glossy lobe seen from the receiver,
        ``principled.glossy_reflectance``): then also returns the (N, 3) radiance it reflects
        of the world, from the same rays — each ray's L V reflect / (K (p_map + p_cos)), the
        balance heuristic of both techniques (p_cos alone for a uniform world).
    sampled : the shadow test of the world-map technique's rays, when it differs from
        ``occluded`` (the cosine rays'): Cycles samples a textured world as a light (its
        shadow rays lifted by the shadow terminator offset, ``terminator.ShadowStarts``) and
        finds it by the BSDF's rays too (not lifted); a uniform world it finds by those alone.
    variance : an (N,) array that gets the variance of the luminance of the hidden part's
        estimate (``hidden_variance``; left as it is where no ray is drawn), for the filter of
        a pixel's world light (docs/gi_pipeline.md "The world's light filtered").
    single : one ray a stratum, not one of each technique (``one_technique``: a bounce hit's
        world light, whose mean over the many rays that read it is what counts).
    rest : callable(point indices) -> (N, K', 2), the strata of the map's and cosine rays when
        they differ from the sun's (a whole image's pixel centres: ``passes.world_strata_side``);
        None: ``strata``'s.
    fewer : (N,) bool, with ``rest``: the points whose map and cosine rays take ``rest``'s
        strata; the others take ``strata``'s (``passes.world_fewer_pixels``). None: all.

    With a ``Sun`` and at least 2 × 2 strata (not single, no ``reflect``), the sun's hidden part
    is estimated apart (``_sun_hidden``) and the map's and cosine rays landing in it count
    nothing."""
    p = np.asarray(p, np.float64)
    n = np.asarray(n, np.float64)
    if rest is not None and fewer is not None:
        return _world_direct_split(world, p, n, occluded, strata, sampled, variance, single,
                                   held, rest, np.asarray(fewer, bool))
    value = unshadowed(world, n)
    lit = np.flatnonzero(any_along(value > 0))
    glossy = np.zeros_like(value)
    if len(lit) == 0 or occluded is None:
        return value if reflect is None else (value, glossy)
    square = strata(lit)  # (M, K, 2)
    sun_square = square
    if rest is not None:
        square = rest(lit)  # (M, K', 2)
    split = single and not world.uniform
    if split:
        mapped, square = one_technique(square)
        dirs = np.empty(square.shape[:-1] + (3,))  # each stratum's direction by its technique
        dirs[mapped] = sample_world(world, square[mapped])
        rows = np.nonzero(~mapped)[0]
        dirs[~mapped] = _cosine(n[lit][rows], square[~mapped][:, None])[:, 0]
    else:
        dirs = _cosine(n[lit], square) if world.uniform else \
            np.concatenate([sample_world(world, square), _cosine(n[lit], square)], axis=1)
    cos = np.einsum("mkc,mc->mk", dirs, n[lit])
    radiance = world_radiance(world, dirs)
    # the density the rays were drawn with (both techniques' sum; the cosine's alone for a
    # uniform world; one of the two at a time: their mean), so that the ratio weighs each ray
    # by L cos / pdf
    pdf = (0.0 if world.uniform else radiance @ LUMINANCE / world.total) + \
        np.maximum(cos, 0.0) / math.pi
    if split:
        pdf = 0.5 * pdf
    f = radiance * (np.maximum(cos, 0.0) / np.maximum(pdf, 1e-30))[..., None]  # (M, 2K, 3)
    up = cos > 0
    sunny = world.sun is not None and not single and reflect is None and \
        sun_square.shape[1] >= DIFFERENCE_STRATA
    if sunny:  # the sun is its own technique's (``_sun_hidden``): the rays that land in it
        # carry nothing here and are not traced
        in_sun = radiance @ LUMINANCE > world.sun.threshold
        f[in_sun] = 0.0
        up &= ~in_sun
    origins = np.repeat(p[lit], dirs.shape[1], axis=0).reshape(dirs.shape)
    blocked = np.zeros(up.shape, bool)
    if sampled is not None and split:  # the map's rays (those of the strata that drew it) apart
        for part, test in ((mapped, sampled), (~mapped, occluded)):
            rays = up & part
            if rays.any():
                blocked[rays] = test(origins[rays], dirs[rays])
    elif sampled is not None and not world.uniform:  # the map's rays (the first K) apart
        k = square.shape[1]
        for part, test in ((slice(0, k), sampled), (slice(k, None), occluded)):
            rays = up[:, part]
            if rays.any():
                blocked[:, part][rays] = test(origins[:, part][rays], dirs[:, part][rays])
    elif up.any():
        blocked[up] = occluded(origins[up], dirs[up])
    # The table's exact unshadowed value less the rays' estimate of the hidden part
    # (Σ L cos / pdf over the K rays of each technique, / K π): exact where every ray sees
    # the world, and unbiased where some are hidden. The visible share Σ seen / Σ all it
    # replaces is a ratio of two estimates, biased where the world is partly hidden (a floor
    # beside a wall: its sun ray seen and its sky ray hidden read fully lit; its sky ray
    # drawn alone, the sun's share lost), which left the HDRI courtyard's walls' bounce
    # light 3% dark (docs/gi_pipeline.md "The world's light where it is partly hidden").
    if sunny:
        sun_hidden, sun_variance = _sun_hidden(world, p[lit], n[lit], sun_square,
                                               sampled or occluded)
        light = value[lit] - (f * blocked[..., None]).sum(axis=1) / (square.shape[1] * math.pi) \
            - sun_hidden
        value[lit] = light if held is False else np.maximum(light, 0.0)
    else:
        value[lit] = hidden_less(value[lit], f, blocked, square.shape[1], held)
    if variance is not None:
        variance[lit] = hidden_variance(f, blocked, square.shape[1]) + \
            (sun_variance if sunny else 0.0)
    if reflect is None:
        return value
    per_technique = square.shape[1]
    shine = radiance * reflect(lit, dirs) / np.maximum(pdf, 1e-30)[..., None]
    glossy[lit] = np.where((up & ~blocked)[..., None], shine, 0.0).sum(axis=1) / per_technique
    return value, glossy


def _world_direct_split(world, p, n, occluded, strata, sampled, variance, single, held, rest,
                        fewer):
    """``world_direct`` at the ``fewer`` points with ``rest``'s strata and at the others with
    ``strata``'s: each group's rays drawn as when it is alone (the strata are hashed per
    point)."""
    value = np.zeros((len(p), 3))
    for group, given in ((fewer, rest), (~fewer, None)):
        own = np.flatnonzero(group)
        if len(own) == 0:
            continue
        part = None if variance is None else variance[own]
        value[own] = world_direct(
            world, p[own], n[own], occluded, lambda points, own=own: strata(own[points]),
            sampled=sampled, variance=part, single=single, held=held,
            rest=None if given is None else (lambda points, own=own: rest(own[points])))
        if variance is not None:
            variance[own] = part
    return value


def _sun_hidden(world: WorldLight, origins, normals, square, occluded):
    """((M, 3) the hidden part of the map's sun at M points, E/π, and (M,) its luminance's
    variance): one ray a stratum drawn by the sun's power (``sample_sun``), f = L cos / pdf; the
    four corner strata first (``direct_light`` ADAPTIVE_FROM, GLSL ``stratum_order``), and
    where those above the horizon agree — the sun all seen or all hidden — the others are not
    drawn, as for a lamp. The estimate is Σ over the hidden rays of f / (the rays drawn · π)."""
    from .direct_light import ADAPTIVE_FROM

    count, k = square.shape[:2]
    side = int(round(math.sqrt(k)))
    dirs = sample_sun(world, square)
    cos = np.einsum("mkc,mc->mk", dirs, normals)
    radiance = world_radiance(world, dirs)
    pdf = radiance @ LUMINANCE / world.sun.total
    f = radiance * (np.maximum(cos, 0.0) / np.maximum(pdf, 1e-30))[..., None]
    counted = cos > 0
    blocked = np.zeros((count, k), bool)
    starts = np.repeat(origins[:, None], k, axis=1)

    def trace(rows, columns):
        rays = np.zeros((len(rows), len(columns)), bool)
        up = counted[np.ix_(rows, columns)]
        if up.any():
            rays[up] = occluded(starts[np.ix_(rows, columns)][up], dirs[np.ix_(rows, columns)][up])
        blocked[np.ix_(rows, columns)] = rays

    if side >= ADAPTIVE_FROM and side * side == k:
        corners = np.array([0, side - 1, side * (side - 1), k - 1])
        rest = np.setdiff1d(np.arange(k), corners)
        trace(np.arange(count), corners)
        seen = any_along(counted[:, corners] & ~blocked[:, corners])
        hidden = any_along(counted[:, corners] & blocked[:, corners])
        settled = seen != hidden
        trace(np.flatnonzero(~settled), rest)  # the settled rows' other rays stay undrawn
        drawn = np.where(settled, 4, k)
    else:
        trace(np.arange(count), np.arange(k))
        drawn = np.full(count, k)
    hidden_f = np.where(blocked[..., None], f, 0.0)   # an undrawn ray is not blocked: 0
    estimate = hidden_f.sum(axis=1) / (drawn[:, None] * math.pi)
    h = (hidden_f @ LUMINANCE) / math.pi
    spread = np.maximum((h * h).sum(axis=1) - h.sum(axis=1) ** 2 / drawn, 0.0) / \
        np.maximum(drawn - 1, 1)
    return estimate, spread / drawn


def world_table(world: WorldLight | None, stream: int = 0) -> np.ndarray:
    """The world as one (rows, max(W + 1, 2 · IRRADIANCE_HEIGHT), 4) float32 texture for
    ``bvh_lights.glsl`` (W the map's width):

    * rows 0 … H − 1, columns 0 … W − 1: radiance rgb, the row's inclusive column CDF;
      column W: the inclusive row CDF in x;
    * rows H … H + IRRADIANCE_HEIGHT − 1, columns 0 … 2·IRRADIANCE_HEIGHT − 1: E(n)/π rgb;
    * then the sun's K pixels (``Sun``), row-major from row H + IRRADIANCE_HEIGHT: (row,
      column, its row's inclusive CDF, its inclusive CDF within the row);
    * the last row: texel 0 = (H, W, IRRADIANCE_HEIGHT, total), texel 1 = (1 = a world, its
      samples' hash stream ``stream`` = its index in the lights list after the lamps,
      1 = uniform (``WorldLight.uniform``), K), texel 2 = (the sun's luminance threshold, its
      total, 0, 0).

    None gives a 1-row table saying "no world"."""
    if world is None:
        table = np.zeros((1, 2, 4), np.float32)
        return table
    h, w = world.radiance.shape[:2]
    ih = IRRADIANCE_HEIGHT
    width = max(w + 1, 2 * ih)
    sun = world.sun
    count = 0 if sun is None else len(sun.rows)
    sun_rows = -(-count // width)
    table = np.zeros((h + ih + sun_rows + 1, width, 4), np.float64)
    table[:h, :w, :3] = world.radiance
    table[:h, :w, 3] = world.column_cdf
    table[:h, w, 0] = world.row_cdf
    table[h:h + ih, :2 * ih, :3] = world.irradiance
    if count:
        texels = np.zeros((sun_rows * width, 4))
        texels[:count] = np.stack([sun.rows, sun.columns, sun.row_cdf, sun.column_cdf], axis=1)
        table[h + ih:h + ih + sun_rows] = texels.reshape(sun_rows, width, 4)
        table[-1, 2, :2] = sun.threshold, sun.total
    table[-1, 0] = (h, w, ih, world.total)
    table[-1, 1] = 1.0, stream, float(world.uniform), count
    return table.astype(np.float32)

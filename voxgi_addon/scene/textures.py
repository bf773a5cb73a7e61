"""Materials per texel: sampling the snapshot's textures at surface points (numpy reference).

A material whose Base Color comes from an image (``MaterialData.base_color_texture`` into
``SceneSnapshot.textures``) is looked up at a surface point's UV — the triangle's corner UVs
(``MeshData.uvs``) interpolated by the point's barycentrics — through the texture's
``uv_transform`` (its Mapping nodes), with its interpolation (Linear: bilinear, Closest) and
extension (Repeat, Extend, Clip) as Cycles' image texture node does
(docs/gi_pipeline.md "Materials per texel").

Minification: each texture gets a mip pyramid (``mip_pyramid``: 2 × 2 box averages, odd sizes
padded by their last row / column), sampled trilinearly at a level of detail from the point's
footprint. Primary pixels take it from the camera (``primary_lod``: the footprint of Cycles'
pixel filter over the pixel's own square, ``filter_footprint``, at the point's distance, over
the square root of the cosine between the ray and the face, in texels of the triangle's UV
density, ``texel_density``) — a stand-in for the pixel filter, which averages a high-frequency
texture over the pixel. Bounce hits sample level 0.

Byte images in sRGB (``TextureData.srgb_bytes``) are blended as Cycles blends them: in their
encoded values, decoded after (``encoded``: level 0 holds sRGB, the levels above the means of
what Cycles reads over each texel), so the border between two texels reads darker than a
linear blend (docs/gi_pipeline.md "Byte images blend in sRGB").

Values are held at half precision (``HALF``), as the GPU atlas (RGBA16F) stores them, so the
numpy reference and the GLSL port (render/shaders/textures.glsl) read the same texels; the
filtering arithmetic is float32 on both. ``pack_atlas`` lays every level of every texture
into one atlas with a table of where each level lies (what the GPU uploads).

Alpha (cut-outs, issue 22 point 2): a material's Alpha is a value or the 4th channel of a
texture (``MaterialData.alpha`` / ``alpha_texture``; the atlas' A channel, 1 for textures
without one). A ray that meets a triangle whose material is not opaque (``SurfaceTextures
.cutout``) counts the hit only when a hash of the ray and the triangle (``cutout_random``,
uniform in [0, 1)) is below the Alpha at the hit (level 0): ``cutout_hits``. Camera, bounce and
shadow rays thus pass through in proportion, as Cycles' stochastic transparency does; numpy
(``raycast``, ``bvh.traverse``) and the GLSL traversal (``bvh_common.glsl``,
``textures.glsl``) run the same test.

Roughness and Metallic per texel (issue 18 point 2, what glTF imports build): a material whose
Roughness or Metallic comes from an image gets a parameter texture (channel 0 roughness,
channel 1 metallic: ``MaterialData.param_texture``) and is followed in the snapshot's
materials by ``PARAM_VARIANTS`` variants of itself at quantized values (``ROUGHNESS_LEVELS`` ×
``METALLIC_LEVELS``). A surface point seen by the camera samples the texture (level 0) and
shades as the variant nearest its texel (``SurfaceTextures.variant_at``): every table the
passes and gathers index by material then holds the texel's values, with no change to the
shading code. Bounce hits shade with the material's own row (the texture's means).

Normal maps (tangent space, ``MaterialData.normal_texture``): what the camera sees shades with
the interpolated normal perturbed as Cycles' Normal Map node does — n = normalize(c.x T +
c.y B + c.z N) for c = 2 · texel − 1 (level 0), B = sign · N × T, then blended towards N by
the Strength — with T the triangle's tangent from its UV map (``face_tangents``: the UV
gradient of a flat triangle, which MikkTSpace equals on flat surfaces; curved low-poly meshes
differ by the per-vertex smoothing MikkTSpace adds). Bounce hits keep the interpolated normal.

Emission per texel (``MaterialData.emission_texture`` × ``emission_strength``): what the camera
sees emits its texel at the emission texture's own ``primary_lod`` (``SurfaceTextures
.emission_at``; ``primary_base`` returns a ``TexelBase`` carrying it, which the passes' emission
term reads through ``texel_emission``). The GPU G-buffer packs it into one float of its base
texture (``pack_emission``). The emissive triangles as a light are split into pieces that each
emit the texture's mean over them (``gi.emitters``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .camera import DEFAULT_FILTER_WIDTH, _frustum, blackman_harris, camera_frame, filter_offsets
from .glass import ray_alpha
from .short_axis import max_along, norm3
from .snapshot import SceneSnapshot, TextureData

MAX_LEVELS = 12              # mip levels kept per texture (level 0 = the image)
MAX_SIZE = 2048              # larger images start at the first level within this size
FOOTPRINT_COS_MIN = 0.05     # the footprint's cosine is held above this (grazing views)
# The pixel-centre pass's texture taps per axis over the pixel's own square (``primary_base``):
# off the edges one point stands for every camera ray of the pixel, and a texture is not
# linear across it (docs/gi_pipeline.md "Textures over the pixel's own square").
TEXTURE_TAPS = 4
TEXTURE_TEXELS = 3 + MAX_LEVELS  # per texture in the GPU table (pack_atlas)
ROUGHNESS_LEVELS = 16        # roughness variants: k / 15
METALLIC_LEVELS = 4          # metallic variants: k / 3
PARAM_VARIANTS = ROUGHNESS_LEVELS * METALLIC_LEVELS
INTERPOLATIONS = {"Linear": 0, "Closest": 1}
EXTENSIONS = {"REPEAT": 0, "EXTEND": 1, "CLIP": 2}
HALF = np.float16
_PYRAMIDS: dict[str, list[np.ndarray]] = {}
MAX_CACHED = 64


def _halve(image: np.ndarray) -> np.ndarray:
    """One mip step: 2 × 2 box averages, an odd size padded with its last row / column."""
    h, w = image.shape[:2]
    if h % 2 and h > 1:
        image = np.concatenate([image, image[-1:]], axis=0)
    if w % 2 and w > 1:
        image = np.concatenate([image, image[:, -1:]], axis=1)
    half = image.dtype.type(0.5)
    if h > 1:
        image = half * (image[0::2] + image[1::2])
    if w > 1:
        image = half * (image[:, 0::2] + image[:, 1::2])
    return image


def within_max_size(pixels: np.ndarray, max_size: int = MAX_SIZE) -> np.ndarray:
    """``pixels`` halved (``mip_pyramid``'s steps, float32) until neither side exceeds
    ``max_size``: what the snapshot keeps of a larger image (the preview never samples finer
    levels than MAX_SIZE)."""
    image = np.asarray(pixels, np.float32)
    while max(image.shape[:2]) > max_size:
        image = _halve(image)
    return image


def srgb_to_linear(values) -> np.ndarray:
    """The sRGB transfer function inverted (encoded values in [0, 1] → linear), float32, as
    Blender's colour management and Cycles decode byte images."""
    values = np.asarray(values, np.float32)
    out = np.maximum(values, np.float32(0.04045), out=np.empty_like(values))
    out += np.float32(0.055)
    out *= np.float32(1 / 1.055)
    np.power(out, np.float32(2.4), out=out)
    low = values <= np.float32(0.04045)
    out[low] = values[low] * np.float32(1 / 12.92)
    return out


def linear_to_srgb(values) -> np.ndarray:
    """The sRGB transfer function (linear → encoded), float32; ``srgb_to_linear`` inverts it."""
    values = np.asarray(values, np.float32)
    values = np.maximum(values, np.float32(0.0), out=np.empty_like(values))
    out = np.maximum(values, np.float32(0.0031308), out=np.empty_like(values))
    np.power(out, np.float32(1 / 2.4), out=out)
    out *= np.float32(1.055)
    out -= np.float32(0.055)
    low = values <= np.float32(0.0031308)
    out[low] = values[low] * np.float32(12.92)
    return out


def encoded(texture: TextureData) -> bool:
    """Does ``texture``'s level 0 hold encoded sRGB, interpolated and then decoded? A byte sRGB
    image (``TextureData.srgb_bytes``) under Linear interpolation: Cycles blends its bytes
    (Closest reads one texel, which decodes to its linear value either way)."""
    return bool(texture.srgb_bytes) and texture.interpolation != "Closest"


_PADS = {"REPEAT": "wrap", "EXTEND": "edge", "CLIP": "constant"}
def _decoded_means(level: np.ndarray, extension: str) -> np.ndarray:
    """(h, w, C) float32: per texel of ``level`` (linear RGB[A]), the mean over its square of
    the colour Cycles reads there from the encoded texels (bilinear in sRGB, then decoded),
    from the 2 × 2 points at a quarter and three quarters of the texel (their bilinear weights
    are 1/4 and 3/4 towards the nearer neighbour; the midpoint rule on each half, which
    overstates the blends' darkening by about a tenth); alpha is kept as it is. Rows go in
    bands, so a 2048² image's temporaries stay small (0.3 s of its pyramid's 0.4–0.6 s)."""
    code = linear_to_srgb(level[..., :3])
    pad = np.pad(code, ((1, 1), (1, 1), (0, 0)), mode=_PADS.get(extension, "edge"))
    q, t = np.float32(0.25), np.float32(0.75)
    means = np.empty(code.shape, np.float32)
    band = 32
    for top in range(0, code.shape[0], band):
        rows = pad[top:top + band + 2]
        centre = rows[1:-1]
        total = np.zeros(centre.shape[:1] + code.shape[1:], np.float32)
        for row in (q * rows[:-2] + t * centre, t * centre + q * rows[2:]):
            middle = t * row[:, 1:-1]
            for points in (middle + q * row[:, :-2], middle + q * row[:, 2:]):
                total += srgb_to_linear(points)
        means[top:top + band] = total * np.float32(0.25)
    return np.concatenate([means, level[..., 3:]], axis=-1)


def mip_pyramid(pixels: np.ndarray, srgb_bytes: bool = False,
                extension: str = "REPEAT") -> list[np.ndarray]:
    """[(h_k, w_k, C) float32] levels of ``pixels`` (row 0 at the bottom; C = 3, or 4 with
    alpha) down to 1 × 1 or MAX_LEVELS, each rounded to half precision (``HALF``); images
    larger than MAX_SIZE start at their first level within it.

    ``srgb_bytes`` (``encoded``: an image Cycles blends in sRGB): level 0 holds the encoded
    colour, which samplers decode after interpolating, and the levels above are box averages of
    what Cycles reads over each level-0 texel (``_decoded_means``, with ``extension``'s
    neighbours), so a minified lookup keeps the darker blends between texels."""
    level = np.asarray(pixels, np.float32)[..., :4]
    while max(level.shape[:2]) > MAX_SIZE:
        level = _halve(level)
    if srgb_bytes:
        first = np.concatenate([linear_to_srgb(level[..., :3]), level[..., 3:]], axis=-1)
        level = _decoded_means(level, extension)
    else:
        first = level
    levels = [first.astype(HALF).astype(np.float32)]
    while len(levels) < MAX_LEVELS and max(level.shape[:2]) > 1:
        level = _halve(level)
        levels.append(level.astype(HALF).astype(np.float32))
    return levels


def pyramid(texture: TextureData) -> list[np.ndarray]:
    """The cached ``mip_pyramid`` of a texture (by its key; by its pixels' identity without)."""
    key = texture.key or f"id{id(texture.pixels)}"
    if encoded(texture):
        key = f"{key}|srgb|{texture.extension}"
    levels = _PYRAMIDS.get(key)
    if levels is None:
        while len(_PYRAMIDS) >= MAX_CACHED:
            _PYRAMIDS.pop(next(iter(_PYRAMIDS)))
        levels = _PYRAMIDS[key] = mip_pyramid(texture.pixels, encoded(texture), texture.extension)
    return levels


def _fetch(image: np.ndarray, x: np.ndarray, y: np.ndarray, extension: str) -> np.ndarray:
    """(N, C) texels at integer (x, y), wrapped by ``extension`` (Clip: 0 outside)."""
    h, w = image.shape[:2]
    if extension == "REPEAT":
        return image[np.mod(y, h), np.mod(x, w)]
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    value = image[np.clip(y, 0, h - 1), np.clip(x, 0, w - 1)]
    if extension == "CLIP":
        value = np.where(inside[:, None], value, np.float32(0.0))
    return value


def sample_level(image: np.ndarray, s: np.ndarray, t: np.ndarray, interpolation: str,
                 extension: str) -> np.ndarray:
    """(N, C) float32 of one level at image coordinates (s, t) (N,) float32 (0 … 1 across the
    image, t = 0 at the bottom row): Closest = the texel containing the point, Linear =
    bilinear between the four nearest texel centres."""
    h, w = image.shape[:2]
    x = s * np.float32(w)
    y = t * np.float32(h)
    if interpolation == "Closest":
        return _fetch(image, np.floor(x).astype(np.int64), np.floor(y).astype(np.int64), extension)
    x = x - np.float32(0.5)
    y = y - np.float32(0.5)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    ix, iy = x0.astype(np.int64), y0.astype(np.int64)
    one = np.float32(1.0)
    bottom = _fetch(image, ix, iy, extension) * (one - fx) + _fetch(image, ix + 1, iy, extension) * fx
    top = _fetch(image, ix, iy + 1, extension) * (one - fx) + _fetch(image, ix + 1, iy + 1, extension) * fx
    return (bottom * (one - fy) + top * fy).astype(np.float32)


def sample_texture(texture: TextureData, uv: np.ndarray, lod=None) -> np.ndarray:
    """(N, 3) float32: ``texture``'s colour at surface UVs (N, 2) through its
    ``uv_transform``, trilinear between mip levels at level of detail ``lod`` (N,) (log2 of
    the footprint in level-0 texels; None: level 0)."""
    return sample_rgba(texture, uv, lod)[:, :3]


def sample_alpha(texture: TextureData, uv: np.ndarray, lod=None) -> np.ndarray:
    """(N,) float32: ``texture``'s 4th channel (its alpha; 1 for a texture without one) at
    surface UVs (N, 2), as ``sample_texture``."""
    return sample_rgba(texture, uv, lod)[:, 3]


def sample_rgba(texture: TextureData, uv: np.ndarray, lod=None) -> np.ndarray:
    """(N, 4) float32: ``sample_texture`` with the 4th channel (1 where the texture has
    three)."""
    levels = pyramid(texture)
    uv = np.asarray(uv, np.float32).reshape(-1, 2)
    a = np.asarray(texture.uv_transform, np.float32)
    s = a[0, 0] * uv[:, 0] + a[0, 1] * uv[:, 1] + a[0, 2]
    t = a[1, 0] * uv[:, 0] + a[1, 1] * uv[:, 1] + a[1, 2]
    interp, ext = texture.interpolation, texture.extension
    decode = encoded(texture)

    def level_value(level, at=slice(None)):
        value = sample_level(levels[level], s[at], t[at], interp, ext)
        if decode and level == 0:  # blended in sRGB, then decoded (Cycles' byte images)
            value[:, :3] = srgb_to_linear(value[:, :3])
        return value

    if lod is None:
        return _rgba(level_value(0))
    lod = np.clip(np.asarray(lod, np.float32), 0.0, np.float32(len(levels) - 1))
    l0 = np.floor(lod).astype(np.int64)
    f = (lod - l0.astype(np.float32))[:, None]
    out = np.zeros((len(uv), levels[0].shape[2]), np.float32)
    for level in np.unique(l0):
        at = np.flatnonzero(l0 == level)
        value = level_value(level, at)
        if level + 1 < len(levels):
            value = value * (np.float32(1.0) - f[at]) + level_value(level + 1, at) * f[at]
        out[at] = value
    return _rgba(out)


def _rgba(values: np.ndarray) -> np.ndarray:
    """(N, 4) of (N, 3) or (N, 4) samples: alpha 1 where the texture has none."""
    if values.shape[1] == 4:
        return values
    return np.concatenate([values, np.ones((len(values), 1), np.float32)], axis=1)


def texture_texels(texture: TextureData) -> float:
    """sqrt(w · h) of the texture's level 0 (as ``pyramid`` keeps it) times the area scale of
    its ``uv_transform``: level-0 texels per unit of surface UV."""
    h, w = pyramid(texture)[0].shape[:2]
    a = np.asarray(texture.uv_transform, np.float64)
    return math.sqrt(w * h) * math.sqrt(abs(a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]))


@dataclass(eq=False)
class SurfaceTextures:
    """What the triangles of a ``SceneTriangles`` need to sample their materials' textures.

    textures : the snapshot's ``TextureData``; slots : (M + 1,) int32 Base Color texture per
    material index (the last row, no material: -1); uvs : (T, 3, 2) float32 corner UVs (zeros
    for meshes without a UV map, as Cycles reads a missing UV map); density : (T,) float32
    level-0 texels per metre of each triangle's texture (0 without one). alpha_slots : (M + 1,)
    int32 the texture whose 4th channel is each material's Alpha (-1: ``alpha_values``);
    alpha_values : (M + 1,) float32 the Alpha of materials without an alpha texture; cutout :
    (T,) bool triangles whose material is not opaque (rays test their Alpha, ``cutout_hits``).
    Glass (``glass.ray_alpha``) lowers the Alpha rays meet; camera rays meet the material's own
    (``camera_alpha_values``, ``camera_cutout``; None without glass): ``for_camera``."""

    textures: tuple
    slots: np.ndarray
    uvs: np.ndarray
    density: np.ndarray = field(default=None)
    alpha_slots: np.ndarray = field(default=None)
    alpha_values: np.ndarray = field(default=None)
    cutout: np.ndarray = field(default=None)
    param_slots: np.ndarray = field(default=None)
    variants: np.ndarray = field(default=None)
    normal_slots: np.ndarray = field(default=None)
    normal_strength: np.ndarray = field(default=None)
    tangents: np.ndarray = field(default=None)
    emission_slots: np.ndarray = field(default=None)
    emission_strength: np.ndarray = field(default=None)
    emission_density: np.ndarray = field(default=None)
    material_base: np.ndarray = field(default=None)
    camera_alpha_values: np.ndarray = field(default=None)
    camera_cutout: np.ndarray = field(default=None)

    def for_camera(self) -> "SurfaceTextures":
        """These textures as camera rays meet them: glass at its own Alpha (opaque, unless a
        cut-out), not at the Alpha other rays meet (``glass.ray_alpha``)."""
        if self.camera_alpha_values is None:
            return self
        return dataclasses.replace(self, alpha_values=self.camera_alpha_values,
                                   cutout=self.camera_cutout, camera_alpha_values=None,
                                   camera_cutout=None)

    def emission_at(self, triangles, materials, b1, b2, lod=None):
        """((N, 3) float64 emission per texel — the texture × the material's strength, negative
        values kept at 0 — where the point's material has an emission texture, else 0; (N,)
        bool which points have one): triangles (N,) indices, materials (N,) their material
        indices, b1, b2 (N,) barycentrics, lod (N,) the emission texture's level of detail or
        None (level 0)."""
        triangles = np.asarray(triangles)
        out = np.zeros((len(triangles), 3))
        if self.emission_slots is None:
            return out, np.zeros(len(triangles), bool)
        row = self.row_of(materials)
        slots = self.emission_slots[row]
        for slot in np.unique(slots[slots >= 0]):
            at = np.flatnonzero(slots == slot)
            value = sample_texture(self.textures[slot], self._uv(
                triangles[at], np.asarray(b1)[at], np.asarray(b2)[at]),
                None if lod is None else np.asarray(lod)[at])
            out[at] = np.maximum(value, 0.0) * self.emission_strength[row[at], None]
        return out, slots >= 0

    def normal_at(self, triangles, materials, b1, b2, normals) -> np.ndarray:
        """(N, 3) unit shading normals ``normals`` (N, 3) (interpolated, unit) perturbed by
        their materials' normal maps (level 0) where they have one (``normal_slots``)."""
        out = np.array(normals, np.float64, copy=True)
        if self.normal_slots is None:
            return out
        triangles = np.asarray(triangles)
        row = self.row_of(materials)
        slots = self.normal_slots[row]
        for slot in np.unique(slots[slots >= 0]):
            at = np.flatnonzero(slots == slot)
            tri = triangles[at]
            colour = sample_texture(self.textures[slot], self._uv(tri, np.asarray(b1)[at],
                                                                  np.asarray(b2)[at]))
            out[at] = perturbed_normals(out[at], self.tangents[tri], colour,
                                        self.normal_strength[row[at]])
        return out

    def variant_at(self, triangles, materials, b1, b2) -> np.ndarray:
        """(N,) int material indices surface points shade with: their own, or for materials
        with a parameter texture (``param_slots``) the variant (``variants`` + ``variant_of``)
        of its texel (level 0); triangles (N,) indices, materials (N,) their materials."""
        materials = np.asarray(materials)
        out = materials.astype(np.int64, copy=True)
        if self.param_slots is None:
            return out
        row = self.row_of(materials)
        slots = self.param_slots[row]
        for slot in np.unique(slots[slots >= 0]):
            at = np.flatnonzero(slots == slot)
            rgba = sample_rgba(self.textures[slot], self._uv(np.asarray(triangles)[at],
                                                             np.asarray(b1)[at], np.asarray(b2)[at]))
            out[at] = self.variants[row[at]] + variant_of(rgba[:, 0], rgba[:, 1])
        return out

    def row_of(self, materials: np.ndarray) -> np.ndarray:
        """(N,) rows of the per-material arrays for material indices (the last: none)."""
        m = np.asarray(materials)
        last = len(self.slots) - 1
        return np.where((m >= 0) & (m < last), m, last)

    def slot_of(self, materials: np.ndarray) -> np.ndarray:
        return self.slots[self.row_of(materials)]

    def alpha_at(self, triangles, materials, b1, b2) -> np.ndarray:
        """(N,) float32 Alpha at surface points (level 0): triangles (N,) indices, materials
        (N,) their material indices, b1, b2 (N,) barycentrics of corners 1 and 2."""
        triangles = np.asarray(triangles)
        row = self.row_of(materials)
        out = np.ones(len(triangles), np.float32)
        if self.alpha_values is not None:
            out = self.alpha_values[row].astype(np.float32)
        if self.alpha_slots is None:
            return out
        slots = self.alpha_slots[row]
        for slot in np.unique(slots[slots >= 0]):
            at = np.flatnonzero(slots == slot)
            out[at] = sample_alpha(self.textures[slot], self._uv(triangles[at], np.asarray(b1)[at],
                                                                 np.asarray(b2)[at]))
        return np.clip(out, 0.0, 1.0)

    def _uv(self, triangles, b1, b2) -> np.ndarray:
        corner = self.uvs[np.asarray(triangles)]
        w1 = np.asarray(b1, np.float32)[:, None]
        w2 = np.asarray(b2, np.float32)[:, None]
        return (np.float32(1.0) - w1 - w2) * corner[:, 0] + w1 * corner[:, 1] + w2 * corner[:, 2]

    def base_at(self, triangles, materials, b1, b2, base, lod=None) -> np.ndarray:
        """``base`` (N, 3) with the textured points' Base Color sampled per texel, clipped to
        [0, 1] as ``preview.passes.principled_table`` clips the values: triangles (N,) indices,
        b1, b2 (N,) the barycentrics of corners 1 and 2, lod (N,) or None (level 0)."""
        slots = self.slot_of(materials)
        out = np.array(base, np.float64, copy=True)
        for slot in np.unique(slots[slots >= 0]):
            at = np.flatnonzero(slots == slot)
            corner = self.uvs[np.asarray(triangles)[at]]
            w1 = np.asarray(b1, np.float32)[at, None]
            w2 = np.asarray(b2, np.float32)[at, None]
            uv = (np.float32(1.0) - w1 - w2) * corner[:, 0] + w1 * corner[:, 1] + w2 * corner[:, 2]
            value = sample_texture(self.textures[slot], uv, None if lod is None else
                                   np.asarray(lod)[at])
            out[at] = np.clip(value, 0.0, 1.0)
        return out


EMISSION_MAX = 65280.0  # the largest emission pack_emission holds (255/256 × 2^16)


def pack_emission(emission) -> np.ndarray:
    """(...) float32 ≥ 2: RGB emissions (..., 3) packed as the G-buffer holds them
    (``textures.glsl`` ``pack_emission``): bits 0x40000000 + a shared exponent E (5 bits,
    2^(E − 15)) and three 8-bit mantissas (0 for no emission), clamped to [0, EMISSION_MAX];
    relative precision 2^-8 of the brightest channel."""
    e = np.clip(np.asarray(emission, np.float32), 0.0, EMISSION_MAX)
    m = max_along(e)
    lit = m >= np.float32(2.0 ** -15)
    x = np.clip(np.floor(np.log2(np.where(lit, m, 1.0))).astype(np.int64) + 1, -14, 16)
    c = np.clip(np.floor(e * np.exp2(8.0 - x)[..., None] + 0.5), 0, 255).astype(np.uint32)
    payload = ((x + 15).astype(np.uint32) << 24) | (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]
    bits = np.uint32(0x40000000) + np.where(lit, payload, 0).astype(np.uint32)
    return bits.view(np.float32)


def unpack_emission(packed) -> np.ndarray:
    """(..., 3) float32 emissions of ``pack_emission``'s floats (...); 0 where a value is
    below 1.5 (no emission texture there)."""
    w = np.asarray(packed, np.float32)
    bits = w.view(np.uint32).astype(np.int64) - 0x40000000
    bits = np.where(w > 1.5, bits, 0)
    c = np.stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255], axis=-1)
    return (c * np.exp2((bits >> 24) - 15.0 - 8.0)[..., None]).astype(np.float32)


def texel_density(positions: np.ndarray, uvs: np.ndarray, world=None) -> np.ndarray:
    """(T,) float32 UV units per metre of each triangle: sqrt(UV area / world area).
    world : (T,) the triangles' |(p1 − p0) × (p2 − p0)| when the caller has them
    (``geometry.world_triangles``' face normal lengths), else computed here."""
    uv = np.asarray(uvs, np.float64)
    if world is None:
        p = np.asarray(positions, np.float64)
        world = norm3(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    world = np.asarray(world, np.float64).reshape(-1)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    flat = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.sqrt(np.divide(flat, world, out=np.zeros_like(world), where=world > 0)).astype(np.float32)


def surface_textures(snapshot: SceneSnapshot, positions: np.ndarray, materials: np.ndarray,
                     uvs: np.ndarray, areas=None) -> SurfaceTextures | None:
    """The ``SurfaceTextures`` of a snapshot's world triangles (None when no material has a
    texture): positions (T, 3, 3), materials (T,), uvs (T, 3, 2); areas : (T,) their
    |(p1 − p0) × (p2 − p0)| when the caller has them (``texel_density``)."""
    textures = tuple(getattr(snapshot, "textures", ()) or ())
    count = len(snapshot.materials) + 1
    slots = np.full(count, -1, np.int32)
    alpha_slots = np.full(count, -1, np.int32)
    alpha_values = np.ones(count, np.float32)
    camera_alpha = np.ones(count, np.float32)
    caustics = bool(getattr(snapshot, "refractive_caustics", True))
    param_slots = np.full(count, -1, np.int32)
    variants = np.full(count, -1, np.int64)
    normal_slots = np.full(count, -1, np.int32)
    normal_strength = np.ones(count, np.float32)
    emission_slots = np.full(count, -1, np.int32)
    emission_strength = np.ones(count, np.float32)
    for i, m in enumerate(snapshot.materials):
        index = int(getattr(m, "emission_texture", -1))
        if 0 <= index < len(textures):
            emission_slots[i] = index
            emission_strength[i] = float(getattr(m, "emission_strength", 1.0))
        index = int(getattr(m, "normal_texture", -1))
        if 0 <= index < len(textures):
            normal_slots[i] = index
            normal_strength[i] = float(getattr(m, "normal_strength", 1.0))
        index = int(getattr(m, "param_texture", -1))
        first = int(getattr(m, "param_variants", -1))
        if 0 <= index < len(textures) and 0 <= first <= len(snapshot.materials) - PARAM_VARIANTS:
            param_slots[i], variants[i] = index, first
        index = int(getattr(m, "base_color_texture", -1))
        if 0 <= index < len(textures):
            slots[i] = index
        index = int(getattr(m, "alpha_texture", -1))
        if 0 <= index < len(textures):
            alpha_slots[i] = index
        alpha_values[i] = np.clip(float(getattr(m, "alpha", 1.0)), 0.0, 1.0)
        camera_alpha[i] = alpha_values[i]
        if alpha_slots[i] < 0:  # glass lets rays through (an alpha texture's glass: not yet)
            alpha_values[i] = ray_alpha(m, caustics)
    transparent = (alpha_slots >= 0) | (alpha_values < 1.0)
    if not (slots >= 0).any() and not transparent.any() and not (param_slots >= 0).any() and \
            not (normal_slots >= 0).any() and not (emission_slots >= 0).any():
        return None
    out = SurfaceTextures(textures, slots, np.asarray(uvs, np.float32))
    scale = np.array([texture_texels(t) for t in textures] + [0.0], np.float64)
    if (emission_slots >= 0).any():
        out.emission_slots, out.emission_strength = emission_slots, emission_strength
        out.material_base = np.zeros((count, 3), np.float32)  # principled_table's base rows
        out.material_base[:-1] = [np.clip(np.nan_to_num(np.asarray(m.base_color[:3], np.float64)),
                                          0, 1) for m in snapshot.materials]
        out.emission_density = (texel_density(positions, uvs, areas) *
                                scale[emission_slots[out.row_of(materials)]]).astype(np.float32)
    if (normal_slots >= 0).any():
        out.normal_slots, out.normal_strength = normal_slots, normal_strength
        out.tangents = face_tangents(positions, uvs)
    if (param_slots >= 0).any():
        out.param_slots, out.variants = param_slots, variants
    if transparent.any():
        out.alpha_slots, out.alpha_values = alpha_slots, alpha_values
        out.cutout = transparent[out.row_of(materials)]
        if (camera_alpha != alpha_values).any():
            out.camera_alpha_values = camera_alpha
            out.camera_cutout = ((alpha_slots >= 0) | (camera_alpha < 1.0))[out.row_of(materials)]
    slot = out.slot_of(materials)
    out.density = (texel_density(positions, uvs, areas) * scale[slot]).astype(np.float32)
    return out


def face_tangents(positions: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(T, 4) float32 per triangle: the unit direction of increasing u over the triangle
    (the UV map's gradient) and the bitangent sign (+1 when the direction of increasing v is
    on the N × T side, N the face normal); zeros for triangles with a degenerate UV map."""
    p = np.asarray(positions, np.float64)
    uv = np.asarray(uvs, np.float64)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    r = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(r) > 1e-20
    inv = np.divide(1.0, r, out=np.zeros_like(r), where=ok)[:, None]
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv
    n = np.cross(e1, e2)
    length = norm3(t)[:, None]
    out = np.zeros((len(p), 4), np.float32)
    out[:, :3] = np.divide(t, length, out=np.zeros_like(t), where=length > 0)
    out[:, 3] = np.where(np.einsum("ij,ij->i", np.cross(n, t), b) < 0.0, -1.0, 1.0)
    return out


def perturbed_normals(normals, tangents, colour, strength) -> np.ndarray:
    """(N, 3) Cycles' Normal Map node (tangent space): unit ``normals`` (N, 3), ``tangents``
    (N, 4) (direction, sign), ``colour`` (N, 3) the map's texels, ``strength`` (N,)."""
    n = np.asarray(normals, np.float64)
    t = np.asarray(tangents, np.float64)
    t_dir = t[:, :3] - n * np.einsum("ij,ij->i", t[:, :3], n)[:, None]  # orthogonal to N
    length = norm3(t_dir)[:, None]
    t_dir = np.divide(t_dir, length, out=np.zeros_like(t_dir), where=length > 1e-12)
    b = t[:, 3:4] * np.cross(n, t_dir)
    c = 2.0 * np.asarray(colour, np.float64) - 1.0
    m = c[:, :1] * t_dir + c[:, 1:2] * b + c[:, 2:3] * n
    m /= np.maximum(norm3(m)[:, None], 1e-12)
    k = np.maximum(np.asarray(strength, np.float64), 0.0)[:, None]
    m = n + (m - n) * k
    out = m / np.maximum(norm3(m)[:, None], 1e-12)
    return np.where(length > 1e-12, out, n)  # no tangent (degenerate UVs): unperturbed


def variant_values(index) -> tuple[np.ndarray, np.ndarray]:
    """(roughness, metallic) of variant ``index`` (0 … PARAM_VARIANTS − 1)."""
    index = np.asarray(index)
    return ((index % ROUGHNESS_LEVELS) / (ROUGHNESS_LEVELS - 1.0),
            (index // ROUGHNESS_LEVELS) / (METALLIC_LEVELS - 1.0))


def variant_of(roughness, metallic) -> np.ndarray:
    """(N,) int: the variant nearest (roughness, metallic), each clipped to [0, 1] (the GLSL
    port is in ``gbuffer_frag.glsl``)."""
    r = np.rint(np.clip(np.asarray(roughness, np.float32), 0, 1) * np.float32(ROUGHNESS_LEVELS - 1))
    m = np.rint(np.clip(np.asarray(metallic, np.float32), 0, 1) * np.float32(METALLIC_LEVELS - 1))
    return (m * ROUGHNESS_LEVELS + r).astype(np.int64)


def _hash(v: np.ndarray) -> np.ndarray:
    """sampling.glsl's ``pcg_hash`` on uint32 arrays."""
    state = v.astype(np.uint32) * np.uint32(747796405) + np.uint32(2891336453)
    word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


CUTOUT_QUANTUM = 4096.0  # rays are hashed on their origin and direction in 1/4096 steps
# The GPU's traversal tests a cut-out's Alpha after a walk and walks again past a hit that does
# not count (bvh_common.glsl bvh_trace): past this many such layers along one ray, the next hit
# counts whatever its Alpha, as Cycles ends a path or a shadow ray past its Transparent bounces
# (8 by default). numpy (``raycast``) has no such cap; no test scene comes near it.
CUTOUT_LAYERS = 16


def _quantized(values) -> np.ndarray:
    """(N, 3) uint32: float32 ``values`` × CUTOUT_QUANTUM floored, as two's-complement bits."""
    q = np.floor(np.asarray(values, np.float32).reshape(-1, 3) * np.float32(CUTOUT_QUANTUM))
    return q.astype(np.int64).astype(np.uint32)


def cutout_random(origins, directions, triangles) -> np.ndarray:
    """(N,) float32 in [0, 1): the hash of a ray (its float32 origin and direction in steps of
    1 / CUTOUT_QUANTUM, so that the GPU's float32 rays and numpy's float64 ones nearly always
    hash alike) and a triangle index, which decides whether the ray passes a cut-out
    (``cutout_hits``); the GLSL port is ``textures.glsl``'s ``cutout_random``."""
    o, d = _quantized(origins), _quantized(directions)
    with np.errstate(over="ignore"):
        h = _hash(np.asarray(triangles).astype(np.int64).astype(np.uint32))
        for column in (o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2]):
            h = _hash(h ^ column)
    return ((h >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0))


def cutout_hits(surface: SurfaceTextures, materials, triangles, b1, b2, origins,
                directions) -> np.ndarray:
    """(N,) bool: does each ray's hit of a cut-out triangle count (``cutout_random`` below the
    Alpha there)? triangles (N,) indices into the ``SceneTriangles``, materials their
    ``materials`` array (all triangles), b1, b2 (N,) the hits' barycentrics, origins,
    directions (N, 3) the rays."""
    triangles = np.asarray(triangles)
    alpha = surface.alpha_at(triangles, np.asarray(materials)[triangles], b1, b2)
    return cutout_random(origins, directions, triangles) < alpha


def pixel_spread(camera, width: int, height: int) -> float:
    """A pixel's width at unit distance (perspective) or in metres (orthographic)."""
    _, _, hx, _ = _frustum(camera, int(width), int(height))
    return float(2.0 * hx / int(width))


def filter_footprint(filter_width: float = DEFAULT_FILTER_WIDTH) -> float:
    """The width (pixels) of the texture footprint one pixel's sample stands for: 2σ of Cycles'
    pixel filter (``camera.blackman_harris`` at Filter Size ``filter_width``) over the pixel's
    own square (|x| ≤ ½), which its passes' samples cover (``filter_offsets``; the filter's
    tails are the neighbours' share). Trilinear sampling at level k (texels 2^k level-0 texels
    wide) has σ = 2^k / 2 (the mip's box and the bilinear tent), so a footprint of 2σ matches
    the filter's σ. 0.53 at Filter Size 1.5; 0 (level 0) for a width ≤ 0."""
    if filter_width <= 0.0:
        return 0.0
    reach = min(float(filter_width), 0.5)
    x = np.linspace(-reach, reach, 2001)
    weight = blackman_harris(x, float(filter_width))
    return float(2.0 * np.sqrt((weight * x * x).sum() / weight.sum()))


def pixel_steps(camera, width: int, height: int) -> np.ndarray:
    """(2, 3) float64 world vectors of one pixel to the right and one pixel down, at unit
    distance (perspective) or in metres (orthographic)."""
    rotation, _ = camera_frame(camera)
    _, _, hx, hy = _frustum(camera, int(width), int(height))
    return np.stack([rotation[:, 0] * (2.0 * hx / int(width)),
                     -rotation[:, 1] * (2.0 * hy / int(height))])


def tap_points(position, normal, camera, width: int, height: int, offsets) -> np.ndarray:
    """(T, N, 3) float64: where the camera rays at the sub-pixel ``offsets`` (T, 2) (x right,
    y down, pixels) of N pixels meet the plane through ``position`` (N, 3), the point each
    pixel's centre sees, with normal ``normal`` (N, 3); a ray along the plane keeps the
    centre's point. gbuffer_frag.glsl ``tap_point`` is its twin."""
    position = np.asarray(position, np.float64)
    normal = np.asarray(normal, np.float64)
    rotation, origin = camera_frame(camera)
    forward = -rotation[:, 2]
    steps = pixel_steps(camera, width, height)
    out = np.empty((len(offsets),) + position.shape)
    if camera.type == "ORTHO":
        for k, (ox, oy) in enumerate(offsets):
            start = position + ox * steps[0] + oy * steps[1]
            along = np.broadcast_to(forward, position.shape)
            out[k] = _on_plane(start, along, position, normal)
        return out
    rel = position - origin
    depth = rel @ forward
    centre = rel / np.where(np.abs(depth) > 1e-12, depth, 1.0)[:, None]
    for k, (ox, oy) in enumerate(offsets):
        out[k] = _on_plane(np.broadcast_to(origin, position.shape),
                           centre + ox * steps[0] + oy * steps[1], position, normal)
    return out


def _on_plane(start, direction, position, normal) -> np.ndarray:
    """(N, 3) start + t·direction on the plane (position, normal); position where the ray runs
    along the plane."""
    across = np.einsum("ij,ij->i", direction, normal)
    reach = np.einsum("ij,ij->i", position - start, normal)
    ok = np.abs(across) > 1e-9 * norm3(direction)
    t = np.divide(reach, across, out=np.zeros_like(reach), where=ok)
    return np.where(ok[:, None], start + t[:, None] * direction, position)


def plane_barycentrics(points, corners) -> tuple[np.ndarray, np.ndarray]:
    """(b1, b2) (N,) of ``points`` (N, 3) in the planes of the triangles ``corners`` (N, 3, 3):
    point = corner 0 + b1 (corner 1 − corner 0) + b2 (corner 2 − corner 0), outside the
    triangle too."""
    corners = np.asarray(corners, np.float64)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d = np.asarray(points, np.float64) - corners[:, 0]
    a11, a12, a22 = (np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2),
                     np.einsum("ij,ij->i", e2, e2))
    r1, r2 = np.einsum("ij,ij->i", e1, d), np.einsum("ij,ij->i", e2, d)
    det = a11 * a22 - a12 * a12
    det = np.where(np.abs(det) > 1e-30, det, 1.0)
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


def primary_lod(density, distance, cos_view, spread: float) -> np.ndarray:
    """(N,) float32 level of detail of a pixel's hit: log2 of its footprint in level-0 texels,
    ``spread`` (``pixel_spread`` × ``filter_footprint``) × distance (1 for an orthographic
    camera: pass ones) / sqrt(|cos| held above FOOTPRINT_COS_MIN) × the triangle's
    ``density``."""
    c = np.maximum(np.abs(np.asarray(cos_view, np.float32)), np.float32(FOOTPRINT_COS_MIN))
    footprint = (np.float32(spread) * np.asarray(distance, np.float32) / np.sqrt(c)
                 * np.asarray(density, np.float32))
    return np.log2(np.maximum(footprint, np.float32(1.0))).astype(np.float32)


def pack_atlas(textures, width: int | None = None):
    """Every level of every texture's pyramid in one atlas (what the GPU samples).

    Returns (atlas (H, W, 4) float32, table (len(textures), TEXTURE_TEXELS, 4) float32): per
    texture, texel 0 = (uv_transform row 0, level count), 1 = (row 1, interpolation), 2 =
    (extension, 1 where level 0 holds encoded sRGB (``encoded``), 0, 0), 3 + k = level k's
    (x0, y0, w, h) in the atlas (row 0 = the images' bottom rows). Levels are packed on shelves, tallest first."""
    rects = []
    for i, texture in enumerate(textures):
        for k, level in enumerate(pyramid(texture)):
            rects.append((level.shape[0], level.shape[1], i, k, level))
    widest = max((r[1] for r in rects), default=1)
    area = sum(r[0] * r[1] for r in rects)
    if width is None:
        width = max(widest, min(8192, 1 << max(0, math.ceil(math.log2(max(1.0, math.sqrt(area) * 1.2))))))
    places = {}
    x = y = shelf = 0
    for h, w, i, k, _ in sorted(rects, key=lambda r: (-r[0], -r[1])):
        if x + w > width:
            x, y, shelf = 0, y + shelf, 0
        places[(i, k)] = (x, y)
        x += w
        shelf = max(shelf, h)
    atlas = np.zeros((max(1, y + shelf), width, 4), np.float32)
    table = np.zeros((max(1, len(textures)), TEXTURE_TEXELS, 4), np.float32)
    for h, w, i, k, level in rects:
        x0, y0 = places[(i, k)]
        atlas[y0:y0 + h, x0:x0 + w, :level.shape[2]] = level
        if level.shape[2] == 3:
            atlas[y0:y0 + h, x0:x0 + w, 3] = 1.0  # no alpha: opaque
        table[i, 3 + k] = (x0, y0, w, h)
    for i, texture in enumerate(textures):
        a = np.asarray(texture.uv_transform, np.float32)
        table[i, 0] = (*a[0], len(pyramid(texture)))
        table[i, 1] = (*a[1], INTERPOLATIONS.get(texture.interpolation, 0))
        table[i, 2, 0] = EXTENSIONS.get(texture.extension, 0)
        table[i, 2, 1] = float(encoded(texture))
    return atlas, table


class TexelBase(np.ndarray):
    """The (N, 3) Base Color ``primary_base`` returns, carrying what the same pixels' camera
    hits emit per texel: ``emission`` (N, 3) and ``emissive`` (N,) bool, the pixels whose
    material has an emission texture (the others emit their material's ``emission``). Arrays
    derived from it (slices, arithmetic) carry neither (None): they are other pixels."""

    emission = None
    emissive = None

    def __array_finalize__(self, obj):
        self.emission = self.emissive = None


def texel_emission(base, emission: np.ndarray) -> np.ndarray:
    """(N, 3) what the camera hits emit: the material table's ``emission`` (N, 3) rows, and
    where ``base`` (``primary_base``'s ``TexelBase``, else anything) says so the emission per
    texel."""
    texels, emissive = getattr(base, "emission", None), getattr(base, "emissive", None)
    if texels is None or emissive is None or not np.any(emissive):
        return emission
    return np.where(np.asarray(emissive)[:, None], texels, emission)


def primary_base(tris, seen, pixels, base, camera, width: int, height: int,
                 filter_width: float = DEFAULT_FILTER_WIDTH, taps: int = 1, share: int = 1):
    """(N, 3) float64 Base Color of the pixels ``pixels`` (N,) flat indices that see a
    surface in ``seen`` (``raycast.PrimaryHits`` with barycentrics): ``base`` (N, 3) (the
    material table's rows) with textured materials sampled per texel at the pixel's
    ``primary_lod`` for Filter Size ``filter_width``; None when the triangles carry no
    textures (use ``base``). A ``TexelBase``: materials with an emission texture give their
    emission per texel there too, at the emission texture's own ``primary_lod``
    (``texel_emission``).

    taps : the Base Color's taps per axis (``TEXTURE_TAPS`` for the pixel-centre pass; 1 for a
    sub-pixel pass, one sample of its pixel): taps > 1 averages taps × taps samples where the
    camera rays at ``camera.filter_offsets(filter_width, taps)`` meet the plane of the
    surface the centre sees (``tap_points``; UVs extrapolated over the triangle's plane), each
    at the level of a tap's share of the footprint (``spread`` / taps), as Cycles' rays
    average the texture over the pixel. The emission per texel stays one sample.
    share : this pass is one of share × share samples of each pixel (a sub-pixel pass:
    ``passes.AA_SIDE``): the Base Color's and the emission's footprints are the pixel's /
    share, so its samples together filter the texture as the centre pass's taps."""
    tex = getattr(tris, "textures", None)
    if tex is None or seen.barycentric is None:
        return None
    pixels = np.asarray(pixels)
    triangle = seen.triangle.ravel()[pixels]
    bary = seen.barycentric.reshape(-1, 2)[pixels]
    position = seen.position.reshape(-1, 3)[pixels]
    if camera.type == "ORTHO":
        distance = np.ones(len(pixels))
    else:
        distance = norm3(position - camera_frame(camera)[1])
    cos = np.einsum("ij,ij->i", seen.face_normal.reshape(-1, 3)[pixels],
                    seen.direction.reshape(-1, 3)[pixels])
    taps = int(taps) if filter_width > 0.0 else 1
    share = max(int(share), 1)
    spread = pixel_spread(camera, width, height) * filter_footprint(filter_width)
    lod = primary_lod(tex.density[triangle], distance, cos, spread / max(taps, share))
    materials = np.asarray(tris.materials)[triangle]
    if taps > 1:
        offsets = filter_offsets(filter_width, taps)
        points = tap_points(position, seen.face_normal.reshape(-1, 3)[pixels], camera, width,
                            height, offsets)
        corners = np.asarray(tris.positions, np.float64)[triangle]
        total = np.zeros((len(pixels), 3))
        for point in points:
            b1, b2 = plane_barycentrics(point, corners)
            total += tex.base_at(triangle, materials, b1, b2, base, lod)
        textured = (tex.slot_of(materials) >= 0)[:, None]
        out = np.where(textured, total / len(points), np.asarray(base, np.float64))
        out = out.view(TexelBase)
    else:
        out = tex.base_at(triangle, materials, bary[:, 0], bary[:, 1], base, lod).view(TexelBase)
    if tex.emission_slots is not None:
        lod = primary_lod(tex.emission_density[triangle], distance, cos, spread / share)
        out.emission, out.emissive = tex.emission_at(triangle, materials, bary[:, 0],
                                                     bary[:, 1], lod)
    return out

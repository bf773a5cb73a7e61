"""Sub-pixel samples resolved from the shaded pixel centres around them (docs/gi_pipeline.md
"Anti-aliasing at the cost of a sample").

The anti-aliased preview draws each edge pixel's sixteen sub-pixel samples of the G-buffer
(where the camera ray of each lands: coverage and material exactly as Cycles' jittered camera
rays see them), but shading each of them — its direct light's shadow rays, its Principled
colours, the gathered terms at its point — cost as much as the whole image's centre pass at
640 × 480. Subpixel reconstruction anti-aliasing (Chajdas, McGuire and Luebke, "Subpixel
reconstruction antialiasing for deferred shading", I3D 2011) shades once per pixel and gives
each geometric sample the light of the shaded pixels around it that lie on its own surface.

Here a sample takes the bilinear blend of the pixel centres around its place in the image (the
2 × 2 whose square holds it) that see its surface (``upsample.same_surface``: same material,
on each other's tangent plane), or, where none of the four does, the nearest such centre among
its pixel's 3 × 3. A textured surface's centre stands in for no sample: it averages the
texture over its whole pixel (``textures.primary_base``'s taps), so a sample taking it would
blur the texture once more (the glTF diorama's Diffuse Color, measured). It is **resolved**
only where that light is known to be smooth: at least ``LEAST_CENTRES`` of the 3 × 3 centres
see its surface and their light spreads by at most ``SPREAD`` of the largest. Elsewhere — a
shadow's or a contact's edge running through the pixel, a sliver of a surface no centre sees —
the sample is shaded as before (the caller's pass over the samples left). The light compared
is the sum of the light the sums carry (``light``, the caller's: Combined before the film's
division).

A sample on a textured surface resolves its light alone (``resolve_samples``' ``by_light``):
the centres' light passes over their colours (``over``; a centre whose colours cannot give
their light back, ``recoverable``, stands in for no such sample) are compared and blended the
same way, and the caller colours the blend with the sample's own colours and emission — a
textured centre's colours are its whole pixel's texture, not the sample's.
"""
from __future__ import annotations

import math

import numpy as np

from .upsample import PLANE_TOLERANCE

__all__ = ["LEAST_CENTRES", "LEAST_COLOUR", "SPREAD", "combined_light", "over", "recoverable",
           "resolve_samples"]

# The most the light of the centres that see a sample's surface may spread (relative to the
# largest) for the sample to take their blend (measured: docs/gi_pipeline.md "Anti-aliasing at
# the cost of a sample")
SPREAD = 0.3
# The fewest of its pixel's 3 × 3 centres that must see a sample's surface: one alone says
# nothing of how the light runs across it
LEAST_CENTRES = 2
# The least colour channel a centre's light is taken back over (a textured sample's); a colour
# black throughout (a metal's diffuse) has no light to give back, and gives 0
LEAST_COLOUR = 1e-3


def over(light, colour) -> np.ndarray:
    """(N, 3) light over colour per channel (light passes are sums of light × colour), 0 where
    the colour is black throughout (float32, as the GPU's ``aa_resolve.glsl``)."""
    light, colour = np.asarray(light, np.float32), np.asarray(colour, np.float32)
    some = np.max(colour, axis=-1, keepdims=True) > 0.0
    return np.where(some, light / np.maximum(colour, np.float32(LEAST_COLOUR)), np.float32(0.0))


def recoverable(colour) -> np.ndarray:
    """(N,) bool: whether a colour's light comes back over it (``over``): every channel at
    least LEAST_COLOUR, or black throughout."""
    colour = np.asarray(colour, np.float32)
    return (np.min(colour, axis=-1) >= LEAST_COLOUR) | (np.max(colour, axis=-1) <= 0.0)


def combined_light(sums) -> np.ndarray:
    """(N,) the light a pixel's sums carry (``passes.SUMS`` by name: emission and the light
    passes, each a sum of light × colour), summed over the channels: what ``resolve_samples``
    compares between centres."""
    return sum(np.asarray(sums[name], np.float64).sum(axis=1)
               for name in ("emission", "diffuse_direct", "diffuse_indirect", "glossy_direct",
                            "glossy_indirect"))


def resolve_samples(centre, light, values, listed, width: int, height: int, offset, sample,
                    spread: float = SPREAD, light_values=None, own_light=None,
                    colours_ok=None):
    """(resolved (N,) bool, blended (N, C) float64) for the samples of one sub-pixel pass at
    the ``listed`` pixels (N,) (flat indices, row 0 on top) of a ``width`` × ``height`` image.

    centre : the pixel centres' G-buffer, dict hit (H, W) bool, material (H, W) int, position
    and normal (H, W, 3); light : (H·W,) the centres' light (see the module's doc); values :
    (H·W, C) what a resolved sample takes, per centre (the centre pass's sums); offset : the
    pass's sub-pixel offset (x right, y down, pixels); sample : the samples' G-buffer in the
    same keys, hit (N,), material (N,), position and normal (N, 3). Both may hold "holdout"
    (a holdout hides what is behind: it sees nothing, but only a holdout stands in for
    another); centre may hold "textured" (H, W) bool: a centre on a textured surface stands
    in for no sample (its colour is its whole pixel's texture, not the sample's). A sample
    not resolved has blended 0 (the caller shades it).

    A sample with ``sample["textured"]`` resolves ``by_light`` (module doc): from the centres
    whose ``colours_ok`` (H·W,) bool, compared by ``own_light`` (H·W,) and blended from
    ``light_values`` (H·W, C) — the caller's light over colour — where it takes them."""
    listed = np.asarray(listed, np.int64)
    count = len(listed)
    values = np.asarray(values)
    blended = np.zeros((count, values.shape[1]))
    resolved = np.zeros(count, bool)
    if count == 0:
        return resolved, blended
    rows, cols = np.divmod(listed, width)
    # the sample's place among the centres (a centre's index is its place): |offset| ≤ ½, so
    # the 2 × 2 centres around it are among its pixel's 3 × 3
    u, v = cols + float(offset[0]), rows + float(offset[1])
    col_step, row_step = math.floor(float(offset[0])), math.floor(float(offset[1]))
    fx, fy = float(offset[0]) - col_step, float(offset[1]) - row_step
    light = np.asarray(light, np.float64)
    flat = {key: np.asarray(centre[key]).reshape(height * width, -1)
            for key in ("hit", "material", "position", "normal")}
    centre_holdout = np.asarray(centre.get("holdout", np.zeros((height, width), bool)),
                                bool).ravel()
    centre_textured = np.asarray(centre.get("textured", np.zeros((height, width), bool)),
                                 bool).ravel()
    s_hit = np.asarray(sample["hit"], bool)
    s_material = np.asarray(sample["material"])
    s_position = np.asarray(sample["position"], np.float32)
    s_normal = np.asarray(sample["normal"], np.float32)
    s_holdout = np.asarray(sample.get("holdout", np.zeros(count, bool)), bool)
    by_light = s_hit & np.asarray(sample.get("textured", np.zeros(count, bool)), bool)
    if by_light.any():
        own_light = np.asarray(own_light, np.float64)
        colours_ok = np.asarray(colours_ok, bool).ravel()
        light_values = np.asarray(light_values)
    # the 3 × 3 centres around the pixel: which see the sample's surface (as
    # upsample.same_surface), how many, their light's spread, the nearest to the sample
    many = np.zeros(count, np.int64)
    low = np.full(count, np.inf)
    high = np.full(count, -np.inf)
    nearest = np.full(count, -1, np.int64)
    distance = np.full(count, np.inf)
    sees_at = {}
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = rows + dr, cols + dc
            inside = (r >= 0) & (r < height) & (c >= 0) & (c < width)
            at = np.clip(r, 0, height - 1) * width + np.clip(c, 0, width - 1)
            step = flat["position"][at] - s_position
            off_plane = np.maximum(np.abs(np.einsum("ij,ij->i", s_normal, step)),
                                   np.abs(np.einsum("ij,ij->i", flat["normal"][at], step)))
            apart = off_plane > PLANE_TOLERANCE * np.sqrt(np.einsum("ij,ij->i", step, step))
            c_hit = flat["hit"][at, 0]
            eligible = ~centre_textured[at]
            if by_light.any():
                eligible = np.where(by_light, colours_ok[at], eligible)
            sees = inside & (c_hit == s_hit) & (centre_holdout[at] == s_holdout) & \
                (~s_hit | ((flat["material"][at, 0] == s_material) & ~apart & eligible))
            sees_at[dr, dc] = sees, at
            many += sees
            compared = light[at] if not by_light.any() else \
                np.where(by_light, own_light[at], light[at])
            low = np.where(sees, np.minimum(low, compared), low)
            high = np.where(sees, np.maximum(high, compared), high)
            d2 = (r - v) ** 2 + (c - u) ** 2
            closer = sees & (d2 < distance)
            nearest, distance = np.where(closer, at, nearest), np.where(closer, d2, distance)
    smooth = (many >= LEAST_CENTRES) & (high - low <= spread * np.maximum(high, 0.0))
    # the 2 × 2 around the sample, bilinear over the ones that see its surface (the pass's
    # offset is every sample's: the same four of the 3 × 3, with the same weights)
    weight = np.zeros(count)
    total = np.zeros_like(blended)
    for dr in (0, 1):
        for dc in (0, 1):
            sees, at = sees_at[row_step + dr, col_step + dc]
            w = np.where(sees & smooth, (fy if dr else 1.0 - fy) * (fx if dc else 1.0 - fx) +
                         1e-6, 0.0)
            weight += w
            taken = values[at] if not by_light.any() else \
                np.where(by_light[:, None], light_values[at], values[at])
            total += w[:, None] * taken
    # (a smooth sample has a nearest centre: at least LEAST_CENTRES see its surface)
    blend = weight > 0.0
    blended[blend] = total[blend] / weight[blend, None]
    alone = smooth & ~blend
    blended[alone] = values[nearest[alone]]
    if by_light.any():
        mine = alone & by_light
        blended[mine] = light_values[nearest[mine]]
    return smooth, blended

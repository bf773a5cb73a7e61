"""What the camera sees through glass: a second layer behind thin glass (issue 22 point 2).

The preview renders glass as a thin surface (``scene.glass``): a camera ray that meets it goes
on in its own direction, carrying the glass' tint and its Fresnel share (``camera_transmittance``).
A camera sample on glass therefore shows two things, summed:

* the glass itself — its reflections (the Principled BSDF's specular layer) and no diffuse
  light (its diffuse part is Base Color × (1 − Transmission Weight)): the *front* layer, the
  preview's own render of the scene, glass and all;
* what is behind it, × its transmittance: the *behind* layer, the same render with the glass
  hidden from camera rays only (``behind_glass``: shadow and bounce rays still meet it as they
  meet it in the front layer), plus the world where nothing is behind (``preview.film``).

``composite`` adds them: Combined = front + weight × (behind + the world behind it), where the
weight is the transmittance of what each camera sample meets, through the pixel filter
(``glass_weight``: the pixel centres everywhere, and the anti-aliased preview's sub-pixel
offsets where the glass' edge crosses a pixel, so that its silhouette is filtered as the front
layer's is). The behind layer shades only the pixels that glass covers (``behind_pixels``),
so it costs in proportion to them. Only Combined carries the light seen through glass (Cycles has it in its
Transmission passes); the others are the front layer's, as Cycles' are at glass (no diffuse).
Both tracers (numpy ``passes.render_passes``, GPU ``render.gpu_preview``) render the layers
with the same code; a scene without glass in view renders one layer, as before.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..scene.camera import DEFAULT_FILTER_WIDTH, filter_samples
from ..scene.glass import camera_transmittance, is_glass
from ..scene.short_axis import max_along
from ..scene.snapshot import RAY_ALL, RAY_CAMERA

__all__ = ["glass_materials", "behind_glass", "glass_weight", "behind_pixels", "composite"]


def glass_materials(snapshot, tris) -> np.ndarray | None:
    """(G,) int32 the glass materials (``scene.glass.is_glass``) of triangles camera rays see,
    or None when the camera sees no glass (one layer is then rendered)."""
    glass = np.asarray([i for i, m in enumerate(snapshot.materials) if is_glass(m)], np.int32)
    if len(glass) == 0 or len(tris) == 0:
        return None
    on = np.isin(np.asarray(tris.materials), glass)
    seen = tris.accepted(RAY_CAMERA) if hasattr(tris, "accepted") else None
    if seen is not None:
        on &= seen
    return glass if on.any() else None


def behind_glass(tris, glass: np.ndarray):
    """``tris`` with the ``glass`` materials' triangles hidden from camera rays only."""
    bits = np.full(len(tris), RAY_ALL, np.uint8) if tris.visibility is None else \
        np.array(tris.visibility, np.uint8, copy=True)
    on = np.isin(np.asarray(tris.materials), glass)
    bits[on] &= np.uint8(RAY_ALL & ~RAY_CAMERA)
    return dataclasses.replace(tris, visibility=bits)


def _edges(weight: np.ndarray) -> np.ndarray:
    """(H, W) bool pixels whose 3 × 3 neighbourhood holds other weights (a glass edge)."""
    height, width = weight.shape[:2]
    padded = np.pad(weight, ((1, 1), (1, 1), (0, 0)), mode="edge")
    out = np.zeros((height, width), bool)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            other = padded[dy:dy + height, dx:dx + width]
            out |= max_along(np.abs(other - weight), 2) > 1e-6
    return out


def glass_weight(materials, hits_at, width: int, height: int,
                 filter_width: float = DEFAULT_FILTER_WIDTH) -> np.ndarray:
    """(H, W, 3) float32: the transmittance camera samples see through, through the pixel
    filter. hits_at(offset) → (material (H, W) int: the material each pixel's camera ray at
    ``offset`` meets, -1 none; cos (H, W): its incidence cosine) — the front layer's camera
    rays; materials : the snapshot's."""
    from .passes import AA_SIDE, filter_coverage

    def weight_at(offset):
        material, cos = hits_at(offset)
        w = camera_transmittance(materials, np.asarray(material).ravel(), np.asarray(cos).ravel())
        return w.reshape(height, width, 3)

    weight = weight_at((0.0, 0.0))
    if filter_width <= 0.0:
        return weight.astype(np.float32)
    edge = _edges(weight)
    if edge.any():
        offsets, weights = filter_samples(filter_width, AA_SIDE)
        total = np.zeros((int(edge.sum()), 3))
        for offset, share in zip(offsets, weights):
            total += share * weight_at(tuple(offset))[edge]
        weight[edge] = total / len(offsets)
    return filter_coverage(weight, filter_width).astype(np.float32)


def behind_pixels(weight: np.ndarray) -> np.ndarray:
    """(H, W) bool the pixels whose behind layer counts: some camera sample sees glass there
    (weight > 0), grown by a pixel so that the behind layer's own edge tests and filter see
    their neighbours. The behind layer shades only these (the rest of the image as background)."""
    seen = max_along(weight, 2) > 0.0
    grown = seen.copy()
    grown[1:] |= seen[:-1]
    grown[:-1] |= seen[1:]
    grown[:, 1:] |= grown[:, :-1].copy()
    grown[:, :-1] |= grown[:, 1:].copy()
    return grown


def composite(front: dict, behind: dict, weight: np.ndarray, background=None) -> dict:
    """The passes of the two layers as one: ``front``'s, with Combined += ``weight`` × (the
    ``behind`` layer's Combined + ``background`` (H, W, 3, the world along the camera rays,
    ``film.background``; None: a black world) where its samples met nothing)."""
    out = dict(front)
    light = np.asarray(behind["Combined"], np.float64)
    if background is not None:
        empty = 1.0 - np.asarray(behind.get("Alpha", np.ones(light.shape[:2])), np.float64)
        held = behind.get("_holdout")
        if held is not None:
            empty = empty - np.asarray(held, np.float64)
        light = light + np.clip(empty, 0.0, 1.0)[..., None] * np.asarray(background, np.float64)
    out["Combined"] = (np.asarray(front["Combined"], np.float64) +
                       np.asarray(weight, np.float64) * light).astype(np.float32)
    return out

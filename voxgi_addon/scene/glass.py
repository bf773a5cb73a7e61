"""Thin glass: what a transmissive material lets through (issue 22 point 2).

A Principled BSDF with Transmission Weight > 0 is glass to Cycles: rays refract into it and out.
The preview does not refract; it renders glass as a *thin surface* — a pane whose two faces are
close and parallel, so that a ray leaves it in the direction it came in (windows, glazing,
bottles seen through one wall) — and lets through what such a pane lets through:

* ``slab_transmittance(cos, ior)``: the share of light a non-absorbing slab passes at incidence
  cosine ``cos`` — (1 − F)/(1 + F) with F the dielectric Fresnel reflectance of one face
  (``fresnel_dielectric``), the two faces and every reflection between them summed (0.923 at
  normal incidence for IOR 1.5, falling to 0 at grazing angles);
* tinted by the material's ``MaterialData.transmission`` (Transmission Weight × (1 − Metallic) ×
  Base Color; Cycles tints each of the two refractions by the square root of the Base Color, so
  a pane passes the Base Color once).

Camera rays see it in colour and by angle (``camera_transmittance``; ``preview.transmission``
renders what is behind the glass and adds it). Every other ray — shadow, bounce, the
voxelizer's coverage — meets it as a cut-out whose Alpha is lowered by the share it lets
through at normal incidence, the tint's mean (``ray_alpha``): rays pass it in that proportion,
as they pass alpha cut-outs (``textures.cutout_hits``). Cycles itself reaches lights through
glass only by caustic paths (its shadow rays stop at glass); at its default Light Paths
(Caustics on, Filter Glossy 1) those carry light through, noisily (about half the sun's for
a clear pane: docs/gi_pipeline.md "Thin glass"). With Refractive Caustics off they do not,
and neither do these rays.
"""
from __future__ import annotations

import numpy as np

__all__ = ["fresnel_dielectric", "slab_transmittance", "transmission_of", "ray_alpha",
           "camera_transmittance", "is_glass"]


def fresnel_dielectric(cos, ior) -> np.ndarray:
    """Unpolarized Fresnel reflectance of a dielectric interface (outside → inside, relative
    index ``ior``) at incidence cosine ``cos`` (its absolute value is used)."""
    c = np.clip(np.abs(np.asarray(cos, np.float64)), 0.0, 1.0)
    eta = np.maximum(np.asarray(ior, np.float64), 1e-6)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / np.maximum(g + c, 1e-12)
    b = (c * (g + c) - 1.0) / np.maximum(c * (g - c) + 1.0, 1e-12)
    out = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0.0, np.clip(out, 0.0, 1.0), 1.0)  # total internal reflection: 1


def slab_transmittance(cos, ior) -> np.ndarray:
    """The share of light a thin non-absorbing slab of index ``ior`` lets through at incidence
    cosine ``cos``: (1 − F)/(1 + F), both faces and the reflections between them."""
    f = fresnel_dielectric(cos, ior)
    return (1.0 - f) / (1.0 + f)


def transmission_of(material) -> np.ndarray:
    """(3,) float64 the material's transmission lobe (zeros for opaque ones)."""
    value = getattr(material, "transmission", None)
    if value is None:
        return np.zeros(3)
    return np.clip(np.nan_to_num(np.asarray(value, np.float64).reshape(-1)[:3]), 0.0, 1.0)


def is_glass(material) -> bool:
    return bool(transmission_of(material).max() > 0.0)


def ray_alpha(material, caustics: bool = True) -> float:
    """The Alpha shadow, bounce and voxel rays meet on ``material``: its own Alpha × (1 − the
    share of light its glass passes at normal incidence, the tint's mean). caustics : Cycles'
    Refractive Caustics (``SceneSnapshot.refractive_caustics``); off, Cycles' paths do not pass
    glass after a diffuse bounce, and shadow rays never do: glass stops them (its own Alpha)."""
    alpha = float(np.clip(float(getattr(material, "alpha", 1.0)), 0.0, 1.0))
    through = transmission_of(material)
    if through.max() <= 0.0 or not caustics:
        return alpha
    passed = float(through.mean() * slab_transmittance(1.0, getattr(material, "ior", 1.5)))
    return alpha * float(np.clip(1.0 - passed, 0.0, 1.0))


def camera_transmittance(materials, indices, cos) -> np.ndarray:
    """(N, 3) float64: what camera rays that meet the materials ``indices`` (N,) (indices into
    ``materials``; out of range or -1: nothing) at incidence cosines ``cos`` (N,) see of what
    is behind: the material's tint × ``slab_transmittance`` (where a cut-out's Alpha lets the
    camera ray pass, it meets what is behind instead)."""
    indices = np.asarray(indices, np.int64)
    table = np.zeros((len(materials) + 1, 3))
    ior = np.full(len(materials) + 1, 1.5)
    for i, m in enumerate(materials):
        table[i] = transmission_of(m)
        ior[i] = float(getattr(m, "ior", 1.5))
    row = np.where((indices >= 0) & (indices < len(materials)), indices, len(materials))
    return table[row] * slab_transmittance(np.asarray(cos, np.float64), ior[row])[:, None]

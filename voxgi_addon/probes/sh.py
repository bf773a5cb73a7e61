"""Real spherical harmonics up to l = 2 (9 coefficients per colour channel) and what the probes
do with them (docs/probes.md "Spherical harmonics").

* ``sample_directions`` — a seeded, near-uniform set of unit directions (spherical Fibonacci
  points under a random rotation): every probe ray of a bake uses the same set.
* ``sh_basis`` — the 9 basis functions at unit directions, ordered l = 0; l = 1, m = −1, 0, 1;
  l = 2, m = −2…2 (Sloan's order: 1, y, z, x, xy, yz, 3z² − 1, xz, x² − y²).
* ``project`` — radiance samples over a uniform direction set → coefficients (Monte Carlo with
  weight 4π/N per sample).
* ``irradiance`` — irradiance E(n) = ∫ L(ω) max(0, n·ω) dω from radiance coefficients, by the
  cosine-lobe convolution of Ramamoorthi & Hanrahan (2001): Â_0 = π, Â_1 = 2π/3, Â_2 = π/4.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["SH_COUNT", "sample_directions", "sh_basis", "project", "project_direction",
           "irradiance", "COSINE_LOBE", "BAND_OF"]

SH_COUNT = 9
BAND_OF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
# Â_l of the clamped cosine kernel (Ramamoorthi & Hanrahan 2001, eq. 8), per coefficient.
COSINE_LOBE = np.array([math.pi, 2 * math.pi / 3, math.pi / 4])[BAND_OF]

_C0 = 0.5 * math.sqrt(1.0 / math.pi)             # 0.282095
_C1 = math.sqrt(3.0 / (4.0 * math.pi))           # 0.488603
_C2 = 0.5 * math.sqrt(15.0 / math.pi)            # 1.092548
_C20 = 0.25 * math.sqrt(5.0 / math.pi)           # 0.315392
_C22 = 0.25 * math.sqrt(15.0 / math.pi)          # 0.546274


def sh_basis(directions) -> np.ndarray:
    """(N, 9) float64 basis values at unit directions (N, 3)."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([
        np.full_like(x, _C0),
        _C1 * y, _C1 * z, _C1 * x,
        _C2 * x * y, _C2 * y * z, _C20 * (3.0 * z * z - 1.0), _C2 * x * z, _C22 * (x * x - y * y),
    ], axis=1)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random 3×3 rotation (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def sample_directions(count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) float64 unit directions, near-uniform over the sphere, fixed by ``seed``.

    Spherical Fibonacci points (equal-area latitude bands, golden-angle longitudes) rotated by
    a random rotation drawn from ``seed``: the same seed always gives the same set.
    """
    count = int(count)
    if count < 1:
        raise ValueError(f"need at least one direction, got {count}")
    i = np.arange(count, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / count
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return dirs @ _random_rotation(np.random.default_rng(seed)).T


def project(radiance, directions) -> np.ndarray:
    """SH coefficients of radiance sampled at near-uniform ``directions``.

    radiance : (..., N, C) samples (C channels, e.g. RGB) along the N directions (N, 3).
    Returns (..., 9, C) float64: Σ_i L(ω_i) Y(ω_i) · 4π / N.
    """
    basis = sh_basis(directions)  # (N, 9)
    values = np.asarray(radiance, dtype=np.float64)
    return np.einsum("nk,...nc->...kc", basis, values) * (4.0 * math.pi / len(basis))


def project_direction(direction, value=1.0) -> np.ndarray:
    """(9, C) coefficients of a Dirac impulse of total power ``value`` (scalar or (C,)) along one
    unit direction: the basis there times the value."""
    basis = sh_basis(np.asarray(direction, np.float64)[None])[0]
    return basis[:, None] * np.atleast_1d(np.asarray(value, np.float64))[None, :]


def irradiance(coefficients, normals) -> np.ndarray:
    """Irradiance E(n) = ∫ L(ω) max(0, n·ω) dω for radiance coefficients.

    coefficients : (9, C) shared by every normal, or (N, 9, C) one set per normal.
    normals : (N, 3) unit. Returns (N, C) float64 (not clamped: L2 ringing can dip below 0).
    """
    c = np.asarray(coefficients, dtype=np.float64)
    basis = sh_basis(normals) * COSINE_LOBE  # (N, 9)
    if c.ndim == 2:
        return basis @ c
    return np.einsum("nk,nkc->nc", basis, c)

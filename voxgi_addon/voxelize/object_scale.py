"""Split an object matrix into the rigid part the runtime can apply and the scale to bake.

Voxels only stay voxels under rotations and translations (Yalçıner 2016, 4.7): a scaled or
sheared object's cache is built from its scaled mesh and the runtime applies the rest.
"""
from __future__ import annotations

import numpy as np

_TOLERANCE = 1e-5


def split_rigid(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polar decomposition of a 4x4 affine matrix: ``M = R · S`` with R rigid and S symmetric.

    Returns rigid (4, 4) float64 (rotation + translation) and stretch (3, 3) float64
    (scale/shear to bake into object-space positions: ``p' = S @ p``). A mirroring matrix keeps
    the reflection in S so R stays a proper rotation.
    """
    m = np.asarray(matrix, np.float64)
    u, sigma, vt = np.linalg.svd(m[:3, :3])
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        sigma[-1] *= -1
        r = u @ vt
    stretch = vt.T @ np.diag(sigma) @ vt
    rigid = np.eye(4)
    rigid[:3, :3] = r
    rigid[:3, 3] = m[:3, 3]
    return rigid, stretch


def is_identity(stretch: np.ndarray) -> bool:
    return bool(np.allclose(stretch, np.eye(3), atol=_TOLERANCE))


def is_uniform(stretch: np.ndarray) -> bool:
    """True for s·I (uniform scale, no shear)."""
    s = np.trace(stretch) / 3.0
    return bool(np.allclose(stretch, s * np.eye(3), atol=_TOLERANCE * max(abs(s), 1.0)))


def stretch_key(stretch: np.ndarray) -> str:
    """A short stable text for a stretch matrix, so equal scales share one baked cache."""
    return ",".join(f"{v:.5g}" for v in np.asarray(stretch).ravel())

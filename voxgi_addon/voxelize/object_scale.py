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


# ------------------------------------------------------------------ skinned objects
# A skinned object's bones carry its whole object matrix at runtime (``scene/skinning``), so its
# cache stays in model space and a unit scale (an armature at 0.01, a mesh in centimetres, as
# Blender's glTF/FBX importers leave Mixamo-style rigs) goes into the voxel's span instead
# (Yalçıner 2016, 4.7: a model-space span of span / s is a world span of span under scale s).

_SKIN_SPAN = "|span:"   # key suffix: the model-space span is the world span divided by this
_SKIN_STRETCH = "|skinstretch:"  # key suffix: the non-uniform part baked into the rest vertices


def skin_bake(matrix: np.ndarray) -> tuple[float, np.ndarray]:
    """How a skinned object's cache is built from its world matrix ``M = R · S`` (polar).

    Returns (s, N): the uniform scale s > 0 that divides the span (model-space voxels of
    span / s are world voxels of one span at rest) and the residual stretch N (3, 3) with
    ``S = s · N``, baked into the rest vertices (``p' = N @ p``; the bones then carry
    ``M @ N⁻¹``). Uniform scale: s = the scale, N = I exactly. Non-uniform scale, shear or
    a mirror: s = |det S|^(1/3) and N the volume-preserving rest (with the reflection), so at
    rest every voxel is still a cube of one world span.
    """
    _, stretch = split_rigid(matrix)
    if is_uniform(stretch):
        return _stable(np.trace(stretch) / 3.0), np.eye(3)
    s = _stable(abs(np.linalg.det(stretch)) ** (1.0 / 3.0))
    return s, np.vectorize(_stable)(stretch / s)


def _stable(value: float) -> float:
    """``value`` to 7 significant digits: the decomposition's rounding noise (0.0254 coming
    back as 0.025399999999999995, differing as the object turns) must not change a cache key;
    the world span moves by under 1e-6 of itself."""
    return float(f"{float(value):.7g}")


def skin_key(mesh: str, s: float, residual: np.ndarray) -> str:
    """The cache key of a skinned mesh baked with ``skin_bake``'s (s, N): the mesh name when
    both are the identity, else the name with the span scale (``repr``: exact) and the
    residual appended (both exact), so objects of one mesh and scale share one cache."""
    key = mesh
    if abs(s - 1.0) > _TOLERANCE:
        key += f"{_SKIN_SPAN}{s!r}"
    if not is_identity(residual):
        key += _SKIN_STRETCH + ",".join(repr(float(v)) for v in np.asarray(residual).ravel())
    return key


def parse_skin_key(key: str, mesh: str = "") -> tuple[float, np.ndarray]:
    """(s, N) that ``skin_key(mesh, s, N)`` was made with (1, I for the plain mesh name)."""
    s, residual = 1.0, np.eye(3)
    if mesh and key.startswith(mesh):
        key = key[len(mesh):]  # a mesh name may itself hold a separator
    head, sep, stretch = key.rpartition(_SKIN_STRETCH)
    if sep:
        residual = np.array([float(v) for v in stretch.split(",")], np.float64).reshape(3, 3)
        key = head
    head, sep, span = key.rpartition(_SKIN_SPAN)
    if sep:
        s = float(span)
    return s, residual

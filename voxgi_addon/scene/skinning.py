"""Linear blend skinning with Blender's Armature-modifier conventions (numpy only).

A skinned object's mesh (and its voxel cache) is stored in the object's REST shape, in object
space. The Armature modifier moves a rest point ``p`` of the object into the armature's space,
applies each bone's ``pose @ inv(rest)`` there, and comes back; the object matrix then places
the result in the world. For bone ``b`` that is, in world space::

    world = arm_world @ pose_b @ inv(rest_b) @ inv(arm_world) @ object_world @ p

(``rest_b`` = ``Bone.matrix_local``, ``pose_b`` = ``PoseBone.matrix``, both in armature space).
Per point the bone matrices are blended linearly with the normalised weights (Blender's
default, "Preserve Volume" off); a point no bone weights stays rigid with the object.
"""
from __future__ import annotations

import numpy as np

from ..errors import VoxGIError
from .short_axis import norm3
from .snapshot import ArmatureData

__all__ = ["skin_matrices", "inverse", "blend_matrices", "skin_points", "transform_points",
           "transform_normals"]


def skin_matrices(armature: ArmatureData, object_world: np.ndarray) -> np.ndarray:
    """Per-bone matrices taking the skinned object's object-space REST positions to world.

    armature : the deforming armature (rest and pose matrices in armature space, world matrix).
    object_world : (4, 4) float64 world matrix of the skinned object.
    Returns (B, 4, 4) float64 ``arm_world @ pose_b @ inv(rest_b) @ inv(arm_world) @ object_world``.
    Raises VoxGIError for mismatched or non-invertible matrices.
    """
    rest = np.asarray(armature.rest_matrices, np.float64)
    pose = np.asarray(armature.pose_matrices, np.float64)
    arm_world = np.asarray(armature.world_matrix, np.float64)
    obj = np.asarray(object_world, np.float64)
    if rest.shape != pose.shape or rest.ndim != 3 or rest.shape[1:] != (4, 4):
        raise VoxGIError(f"armature '{armature.name}': rest {rest.shape} and pose {pose.shape} "
                         "matrices must both be (bones, 4, 4)")
    if arm_world.shape != (4, 4) or obj.shape != (4, 4):
        raise VoxGIError("armature and object world matrices must be 4x4")
    try:
        inv_rest = inverse(rest)
        inv_arm = inverse(arm_world)
    except np.linalg.LinAlgError as error:
        raise VoxGIError(f"armature '{armature.name}' has a singular rest or world matrix") from error
    return arm_world @ pose @ inv_rest @ (inv_arm @ obj)


def inverse(matrices: np.ndarray) -> np.ndarray:
    """``np.linalg.inv`` of (..., 4, 4) float64 matrices, in closed form where they are
    affine (last row 0, 0, 0, 1: every bone and object matrix): the 3 × 3 part's adjugate
    over its determinant. No LAPACK call: on the worker of a busy 2-core machine
    OpenBLAS's thread pool made each ``inv`` of a rig's bones take 5–40 ms (a posed
    update does four). Raises ``np.linalg.LinAlgError`` for a singular matrix, as ``inv``."""
    m = np.asarray(matrices, np.float64)
    if not np.array_equal(m[..., 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], m.shape[:-2] + (4,))):
        return np.linalg.inv(m)
    r = m[..., :3, :3]
    a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
    # rows of the adjugate's transpose: the cofactors (cross products of the other rows)
    cof = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=-2)
    det = np.einsum("...i,...i->...", a, cof[..., 0, :])
    if not np.all(np.isfinite(det)) or np.any(det == 0.0):
        raise np.linalg.LinAlgError("Singular matrix")
    inv_r = np.swapaxes(cof, -1, -2) / det[..., None, None]
    out = np.zeros_like(m)
    out[..., :3, :3] = inv_r
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", inv_r, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def blend_matrices(matrices: np.ndarray, weights: np.ndarray, indices: np.ndarray,
                   fallback: np.ndarray | None = None) -> np.ndarray:
    """Linear blend of bone matrices per point: ``Σ_k w_k · M[idx_k] / Σ_k w_k``.

    matrices : (B, 4, 4) float64, e.g. from ``skin_matrices``.
    weights : (N, 4) float, non-negative (normalised here; they need not sum to 1).
    indices : (N, 4) int bone indices into ``matrices`` (ignored where the weight is 0).
    fallback : (4, 4) matrix for rows whose weights sum to 0 — the skinned object's world
        matrix, as Blender leaves unweighted vertices rigid with the object. Default identity.
    Returns (N, 4, 4) float64.
    """
    mats = np.asarray(matrices, np.float64)
    w = np.clip(np.nan_to_num(np.asarray(weights, np.float64)), 0.0, None)
    idx = np.asarray(indices, np.int64)
    if w.shape != idx.shape or w.ndim != 2:
        raise VoxGIError(f"skin weights {w.shape} and bone indices {idx.shape} must match (N, k)")
    total = w.sum(axis=1)
    used = w > 0
    if used.any() and (idx[used].min() < 0 or idx[used].max() >= len(mats)):
        raise VoxGIError(f"bone index outside the armature's {len(mats)} deform bones")
    idx = np.where(used, idx, 0)
    w = np.divide(w, total[:, None], out=np.zeros_like(w), where=total[:, None] > 0)
    out = np.zeros((len(w), 4, 4))
    for k in range(w.shape[1]):  # a handful of influences: whole-array passes
        out += w[:, k, None, None] * mats[idx[:, k]]
    unweighted = total <= 0
    if unweighted.any():
        out[unweighted] = np.eye(4) if fallback is None else np.asarray(fallback, np.float64)
    return out


def transform_points(matrices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply (4, 4) or per-point (N, 4, 4) affine matrices to (N, 3) points → (N, 3) float64."""
    m = np.asarray(matrices, np.float64)
    p = np.asarray(points, np.float64)
    if m.ndim == 2:
        return p @ m[:3, :3].T + m[:3, 3]
    return np.einsum("nij,nj->ni", m[:, :3, :3], p) + m[:, :3, 3]


def _cofactor(linear: np.ndarray) -> np.ndarray:
    """Cofactor matrices det(A)·inv(A)ᵀ of (..., 3, 3): columns are cross products of A's columns."""
    a, b, c = linear[..., :, 0], linear[..., :, 1], linear[..., :, 2]
    return np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=-1)


def transform_normals(matrices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Transform (N, 3) normals by the linear part of (4, 4) or (N, 4, 4) matrices, renormalised.

    Uses the cofactor matrix (the inverse transpose up to a positive factor for
    orientation-preserving matrices), so normals stay perpendicular to the surface under the
    non-rigid blended matrices of skinning. Returns (N, 3) float64 unit vectors (0 where the
    result degenerates).
    """
    m = np.asarray(matrices, np.float64)
    n = np.asarray(normals, np.float64)
    cof = _cofactor(m[..., :3, :3])
    det = np.einsum("...i,...i->...", m[..., :3, 0], cof[..., :, 0])
    if m.ndim == 2:
        out = n @ cof.T * np.sign(det)
    else:
        out = np.einsum("nij,nj->ni", cof, n) * np.sign(det)[:, None]
    length = norm3(out)[:, None]
    return np.divide(out, length, out=np.zeros_like(out), where=length > 1e-12)


def skin_points(armature: ArmatureData, object_world: np.ndarray, positions: np.ndarray,
                weights: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """World positions of skinned REST points (vertices or voxel centres) in the current pose.

    positions : (N, 3) object space, rest shape. weights : (N, 4), indices : (N, 4) as in
    ``SkinData``. Returns (N, 3) float64 world positions — what Blender's evaluated (posed)
    mesh holds, mapped through the object's world matrix.
    """
    bones = skin_matrices(armature, object_world)
    blended = blend_matrices(bones, weights, indices, fallback=object_world)
    return transform_points(blended, positions)

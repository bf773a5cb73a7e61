"""Node transforms: TRS with Euler XYZ rotations, composed into world matrices (numpy)."""
from __future__ import annotations

import numpy as np

from .model import Node


def euler_xyz_matrix(rotation) -> np.ndarray:
    """(3, 3) float64 rotation of Euler XYZ angles (radians): X applied first (R = Rz Ry Rx)."""
    x, y, z = (float(a) for a in np.asarray(rotation, np.float64).reshape(3))
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def local_matrix(translation, rotation, scale) -> np.ndarray:
    """(4, 4) float64 ``T @ R @ S``: scale, then rotate (Euler XYZ), then translate."""
    m = np.eye(4)
    m[:3, :3] = euler_xyz_matrix(rotation) * np.asarray(scale, np.float64).reshape(1, 3)
    m[:3, 3] = np.asarray(translation, np.float64).reshape(3)
    return m


def compose_world(nodes: list[Node]) -> None:
    """Set every node's ``world`` (float32) from the stored transforms, parents first.

    ``world = world(parent) @ parent_inverse @ T @ R @ S`` in float64, rounded once.
    """
    worlds: list[np.ndarray] = []
    for node in nodes:
        local = np.asarray(node.parent_inverse, np.float64) @ local_matrix(
            node.translation, node.rotation, node.scale)
        world = local if node.parent < 0 else worlds[node.parent] @ local
        worlds.append(world)
        node.world = world.astype(np.float32)

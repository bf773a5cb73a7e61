"""The scene's triangles in world space, for exact ray casting (primary visibility, shadows).

Static and rigid objects are placed with their world matrix; skinned objects with linear blend
skinning of their rest-pose vertices (the snapshot stores skinned meshes in the rest pose):
``world = Σ_b w_b · (arm_world · pose_b · rest_b⁻¹ · arm_world⁻¹ · object_world) · p``, which is
what Blender's Armature modifier does. A vertex whose weights are all zero follows the object.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skinning import skin_points
from .snapshot import MeshData, ObjectData, SceneSnapshot

__all__ = ["SceneTriangles", "world_triangles", "object_vertices_world"]


@dataclass(frozen=True, eq=False)
class SceneTriangles:
    """All visible triangles of a snapshot, in world space.

    positions : (T, 3, 3) float64, world-space corners (metres).
    normals : (T, 3) float64 unit face normals (right-hand winding; zero for degenerate triangles).
    materials : (T,) int32 index into ``SceneSnapshot.materials`` (-1 = none).
    objects : (T,) int32 index into ``SceneSnapshot.objects``.
    """

    positions: np.ndarray
    normals: np.ndarray
    materials: np.ndarray
    objects: np.ndarray

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(3,) min and max corner of all triangles (zeros when empty)."""
        if len(self.positions) == 0:
            return np.zeros(3), np.zeros(3)
        flat = self.positions.reshape(-1, 3)
        return flat.min(axis=0), flat.max(axis=0)


def object_vertices_world(obj: ObjectData, mesh: MeshData, snapshot: SceneSnapshot) -> np.ndarray:
    """(V, 3) float64 world positions of ``mesh``'s vertices as placed (and posed) by ``obj``."""
    p = np.asarray(mesh.positions, dtype=np.float64)
    world_matrix = np.asarray(obj.world_matrix, dtype=np.float64)
    armature = snapshot.armatures.get(obj.armature) if obj.armature is not None else None
    if obj.kind != "skinned" or mesh.skin is None or armature is None or len(armature.bone_names) == 0:
        return p @ world_matrix[:3, :3].T + world_matrix[:3, 3]
    return skin_points(armature, world_matrix, p, mesh.skin.weights, mesh.skin.bone_indices)


def world_triangles(snapshot: SceneSnapshot) -> SceneTriangles:
    """Every triangle of every object in ``snapshot`` in world space (see ``SceneTriangles``).

    Objects whose mesh is missing from the snapshot are skipped. Triangles keep the order of
    ``snapshot.objects`` then of each mesh's triangles.
    """
    positions, materials, objects = [], [], []
    for index, obj in enumerate(snapshot.objects):
        mesh = snapshot.meshes.get(obj.mesh)
        if mesh is None or len(mesh.triangles) == 0:
            continue
        vertices = object_vertices_world(obj, mesh, snapshot)
        positions.append(vertices[np.asarray(mesh.triangles, dtype=np.int64)])
        materials.append(np.asarray(mesh.triangle_materials, dtype=np.int32))
        objects.append(np.full(len(mesh.triangles), index, dtype=np.int32))
    if not positions:
        empty = np.zeros(0, np.int32)
        return SceneTriangles(np.zeros((0, 3, 3)), np.zeros((0, 3)), empty, empty.copy())
    tri = np.concatenate(positions)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    return SceneTriangles(tri, normal, np.concatenate(materials), np.concatenate(objects))

"""The in-memory GFG scene: plain dataclasses over numpy arrays (no bpy).

The reader fills these with read-only views into the file's buffer (no copies); the writer
takes them from any source. Indices refer to positions in ``GFGScene`` lists; -1 means none.
Matrices are row-major (4, 4) float32 for column vectors.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...probes.grid import ProbeGrid  # the baked grid is the file's model too
from ...voxelize.cache import VoxelCache
from ...voxelize.scene_caches import ObjectBinding, SkippedMesh
from .spec import (
    AnimLayout,
    Interpolation,
    Logic,
    MaterialLogic,
    NodeKind,
    QuatLayout,
    Topology,
)


def _identity():
    return np.eye(4, dtype=np.float32)


@dataclass
class VertexComponent:
    """One per-vertex attribute.

    logic : ``spec.Logic`` (POSITION, UV, NORMAL, ...); several components may share a logic
        (UV sets, in order).
    data_type : GFG data type code (``data_types``); ``values`` is its storage,
        shape (V, components), e.g. (V, 3) float32 for FLOAT_3, (V, 1) uint32 for packed words.
    """

    logic: int
    data_type: int
    values: np.ndarray


@dataclass
class MaterialRange:
    """Triangles ``indices[index_offset : index_offset + index_count]`` use ``material``."""

    material: int
    index_offset: int
    index_count: int


@dataclass
class Mesh:
    """A single-indexed mesh, ready for one vertex-buffer and one index-buffer upload.

    indices : (I,) uint8/uint16/uint32, or None for a non-indexed mesh.
    aabb : (2, 3) float32 object-space min and max of the positions.
    skeleton : index into ``GFGScene.skeletons`` that WEIGHT_INDEX values refer to.
    interleaved : one vertex block with every component (True) or one block each (False).
    """

    name: str
    components: list[VertexComponent]
    indices: np.ndarray | None
    aabb: np.ndarray
    topology: int = Topology.TRIANGLES
    ranges: list[MaterialRange] = field(default_factory=list)
    skeleton: int = -1
    interleaved: bool = True

    @property
    def vertex_count(self) -> int:
        return len(self.components[0].values) if self.components else 0

    def component(self, logic: int, set_index: int = 0) -> VertexComponent | None:
        """The ``set_index``-th component with this logic, or None."""
        found = [c for c in self.components if c.logic == logic]
        return found[set_index] if set_index < len(found) else None

    @property
    def positions(self) -> np.ndarray | None:
        c = self.component(Logic.POSITION)
        return None if c is None else c.values


@dataclass
class Material:
    """A material: ``logic`` (``spec.MaterialLogic``), uniforms and texture paths by slot.

    uniforms : {slot: (k,) float32, 1 ≤ k ≤ 4}; textures : {slot: UTF-8 path, relative to the
    file's folder unless absolute, '/' separators}.
    """

    name: str
    logic: int = MaterialLogic.PRINCIPLED
    uniforms: dict[int, np.ndarray] = field(default_factory=dict)
    textures: dict[int, str] = field(default_factory=dict)


@dataclass
class Skeleton:
    """Bones of an armature in its rest (bind) pose, parents before children.

    parents : (B,) int32, -1 for roots; flags : (B,) uint32 ``spec.BoneFlag`` bits.
    heads, tails : (B, 3) float32 armature space; rolls : (B,) float32 radians.
    rest_matrices : (B, 4, 4) float32 bone-to-armature matrices (Blender ``Bone.matrix_local``).
    """

    name: str
    bone_names: tuple[str, ...]
    parents: np.ndarray
    flags: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    rolls: np.ndarray
    rest_matrices: np.ndarray

    @property
    def bone_count(self) -> int:
        return len(self.bone_names)


@dataclass
class Pose:
    """Per-bone local pose of an armature node (relative to the rest pose).

    rotations : (B, 4) float32 quaternions WXYZ; locations, scales : (B, 3) float32.
    """

    rotations: np.ndarray
    locations: np.ndarray
    scales: np.ndarray


@dataclass
class Node:
    """A scene-hierarchy node (an object).

    Local transform: scale, then Euler XYZ ``rotation`` (radians), then ``translation``;
    ``world = world(parent) @ parent_inverse @ T @ R @ S`` (see ``transforms.compose_world``).
    kind : ``spec.NodeKind``. mesh : mesh index (MESH nodes). skeleton : skeleton index
    (ARMATURE nodes). armature_node : the ARMATURE node deforming a skinned MESH node.
    """

    name: str
    parent: int = -1
    kind: int = NodeKind.EMPTY
    mesh: int = -1
    skeleton: int = -1
    armature_node: int = -1
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    scale: np.ndarray = field(default_factory=lambda: np.ones(3, np.float32))
    parent_inverse: np.ndarray = field(default_factory=_identity)
    world: np.ndarray = field(default_factory=_identity)
    pose: Pose | None = None


@dataclass
class Animation:
    """Skeletal animation: key times, optional hip translation, per-bone quaternions.

    times : (K,) float32 seconds. rotations : (K, B, 4) float32 quaternions in ``quat_layout``
    order (a transposed view when the file is bone-major). hip_translations : (K, 3) float32
    local location of bone ``hip_bone``, or None (ONLY_QUATERNION).
    node : the ARMATURE node it plays on (-1: any node of ``skeleton``).
    """

    name: str
    skeleton: int
    times: np.ndarray
    rotations: np.ndarray
    hip_translations: np.ndarray | None = None
    hip_bone: int = 0
    node: int = -1
    frame_rate: float = 24.0
    interpolation: int = Interpolation.SLERP
    layout: int = AnimLayout.BONES_OF_KEYS
    quat_layout: int = QuatLayout.WXYZ


@dataclass
class VoxelSet:
    """The voxel caches of a scene (``mesh_caches.CacheBuildResult`` without its reports).

    keys : every cache key in order (a key whose cascades are all skipped has no cache).
    caches : the engine's ``VoxelCache`` objects, packed words as views into the file.
    """

    base_span: float
    cascade_count: int
    keys: list[str]
    caches: list[VoxelCache]
    bindings: dict[str, ObjectBinding] = field(default_factory=dict)
    skipped: list[SkippedMesh] = field(default_factory=list)


@dataclass
class RawSection:
    """A section the writer copies verbatim (kinds of newer versions, tests)."""

    kind: bytes
    payload: bytes
    flags: int = 0
    version: int = 1


@dataclass
class SkippedSection:
    """A section the reader did not understand and skipped."""

    index: int
    kind: bytes
    size: int


@dataclass
class GFGScene:
    """Everything a GFG file holds."""

    nodes: list[Node] = field(default_factory=list)
    meshes: list[Mesh] = field(default_factory=list)
    materials: list[Material] = field(default_factory=list)
    skeletons: list[Skeleton] = field(default_factory=list)
    animations: list[Animation] = field(default_factory=list)
    voxels: VoxelSet | None = None
    probe_grids: list[ProbeGrid] = field(default_factory=list)
    extra_sections: list[RawSection] = field(default_factory=list)
    skipped_sections: list[SkippedSection] = field(default_factory=list)
    version: tuple[int, int] | None = None  # set by the reader

"""Small GFG scenes with every section kind, for the format tests (plain numpy)."""
import numpy as np
from meshes import box, tube

from voxgi.voxgi_addon.files.gfg import (
    Animation,
    GFGScene,
    Material,
    Node,
    Pose,
    ProbeGrid,
    RawSection,
    Skeleton,
    VertexTypes,
    VoxelSet,
    build_mesh,
    compose_world,
)
from voxgi.voxgi_addon.files.gfg.data_types import code_of
from voxgi.voxgi_addon.files.gfg.model import Mesh, VertexComponent
from voxgi.voxgi_addon.files.gfg.spec import Logic, MaterialLogic, NodeKind, PrincipledSlot, Topology
from voxgi.voxgi_addon.voxelize.cache import VoxelCache
from voxgi.voxgi_addon.voxelize.scene_caches import ObjectBinding, SkippedMesh


def _corner_normals(positions, triangles):
    p = positions[triangles]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.repeat(n[:, None, :], 3, axis=1).astype(np.float32)


def skeleton(bones=3):
    heads = np.array([[0, 0, i] for i in range(bones)], np.float32)
    rest = np.tile(np.eye(4, dtype=np.float32), (bones, 1, 1))
    rest[:, :3, 3] = heads
    return Skeleton("Rig", tuple(f"Bone.{i}" for i in range(bones)),
                    np.arange(-1, bones - 1, dtype=np.int32), np.full(bones, 3, np.uint32), heads,
                    heads + np.float32([0, 0, 1]), np.linspace(0, 0.5, bones).astype(np.float32), rest)


def voxel_cache(key, cascade, count, rng, skinned=False):
    words = lambda: rng.integers(0, 2**32, count, dtype=np.uint64).astype(np.uint32)  # noqa: E731
    return VoxelCache(key, cascade, 0.25 * 2**cascade, np.array([-3, 0, 2]), np.array([8, 9, 10]),
                      words(), words(), words(), words() if skinned else None,
                      words() if skinned else None)


def probe_grid(rng):
    """Two active volumes of a 2×2×2 grid (cells 0 and 7) sharing their middle corner probe."""
    cells = np.array([0, 7], np.uint32)
    xyz = np.array([[0, 0, 0], [1, 1, 1]])[:, None, :] + np.array(
        [[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])[None]
    corners = xyz[..., 0] + 3 * (xyz[..., 1] + 3 * xyz[..., 2])
    unique, probes = np.unique(corners, return_inverse=True)
    p = len(unique)
    return ProbeGrid(np.array([-1.0, -1.0, 0.0]), [0.5, 0.5, 0.75], np.array([2, 2, 2]),
                     rng.normal(size=(p, 3)).astype(np.float32),
                     rng.normal(size=(p, 9, 3)).astype(np.float32), cells,
                     probes.reshape(2, 8).astype(np.uint32),
                     rng.integers(0, 2**63, (2, 8), dtype=np.uint64),
                     validity=rng.random(p).astype(np.float32),
                     flags=rng.integers(0, 4, p).astype(np.uint32), mask_threshold=0.5)


def full_scene(voxels_per_cache=40, seed=0) -> GFGScene:
    """Two materials, four meshes (interleaved, separate, skinned, points), three nodes with a
    pose, a 3-bone skeleton with an animation, a voxel set with three caches, a probe grid."""
    rng = np.random.default_rng(seed)
    v, t = box()
    uvs = rng.random((len(t), 3, 2)).astype(np.float32)
    materials = [
        Material("Red", MaterialLogic.PRINCIPLED,
                 {PrincipledSlot.BASE_COLOR: np.float32([0.8, 0.1, 0.1, 1]),
                  PrincipledSlot.ROUGHNESS: np.float32([0.4])},
                 {PrincipledSlot.BASE_COLOR: "textures/red é.png"}),
        Material("Grey", MaterialLogic.LAMBERT, {0: np.float32([0.5, 0.5, 0.5])}),
    ]
    slots = np.arange(len(t)) % 3
    boxes = build_mesh("Box", v, t, corner_normals=_corner_normals(v, t), corner_uvs=uvs,
                       triangle_slots=slots, slot_materials=[0, 1, -1])
    packed = build_mesh("Packed", v, t, corner_normals=_corner_normals(v, t), corner_uvs=uvs,
                        types=VertexTypes("HALF_3", "CUSTOM_1_15N_16N", "UNORM16_2"), interleaved=False)
    tv, tt = tube(rings=4, segments=6)
    w = rng.random((len(tv), 4))
    skinned = build_mesh("Skin", tv, tt, corner_normals=_corner_normals(tv, tt), weights=w,
                         bone_indices=rng.integers(0, 3, (len(tv), 4)), skeleton=0,
                         types=VertexTypes(weight="UNORM16_4", weight_index="UINT16_4"))
    points = Mesh("Points", [VertexComponent(Logic.POSITION, code_of("FLOAT_3"),
                                             rng.normal(size=(5, 3)).astype(np.float32))],
                  None, np.zeros((2, 3), np.float32), Topology.POINTS)
    nodes = [
        Node("Root", translation=np.float32([1, 2, 3])),
        Node("Box", 0, NodeKind.MESH, mesh=0, rotation=np.float32([0.1, 0.2, 0.3]),
             scale=np.float32([1, 2, 1]), parent_inverse=np.diag(np.float32([1, 1, 1, 1]))),
        Node("Rig", 0, NodeKind.ARMATURE, skeleton=0,
             pose=Pose(np.tile(np.float32([1, 0, 0, 0]), (3, 1)), np.zeros((3, 3), np.float32),
                       np.ones((3, 3), np.float32))),
        Node("Skin", 2, NodeKind.MESH, mesh=2, armature_node=2),
        Node("Points", -1, NodeKind.MESH, mesh=3),
        Node("Packed", -1, NodeKind.MESH, mesh=1),
    ]
    compose_world(nodes)
    q = rng.normal(size=(4, 3, 4)).astype(np.float32)
    animation = Animation("Wave", 0, np.float32([0, 1 / 24, 2 / 24, 0.5]), q / np.linalg.norm(q, axis=2, keepdims=True),
                          rng.normal(size=(4, 3)).astype(np.float32), node=2)
    caches = [voxel_cache("Box", 0, voxels_per_cache, rng), voxel_cache("Box", 1, voxels_per_cache // 2, rng),
              voxel_cache("Skin", 0, voxels_per_cache, rng, skinned=True)]
    voxels = VoxelSet(0.25, 2, ["Box", "Skin", "Empty"], caches,
                      {"Box": ObjectBinding("Box", np.eye(4), "static"),
                       "Skin": ObjectBinding("Skin", np.diag([1.0, 1, 1, 1]) * 2, "skinned")},
                      [SkippedMesh("Skin", 1, 0.5, (3, 2000, 4))])
    return GFGScene(nodes, [boxes, packed, skinned, points], materials, [skeleton()], [animation], voxels,
                    [probe_grid(rng)], [RawSection(b"FUTR", b"future data\x00\x01")])


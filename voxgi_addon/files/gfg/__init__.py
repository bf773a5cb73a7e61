"""GFG-like asset files (after Yalçıner 2016, appendix B), numpy only: see ``docs/gfg.md``.

Modules:
  spec           constants, enums and the on-disk struct layouts
  data_types     the original's data type codes, with float codecs
  errors         GFGError, the one error type
  model          GFGScene and its parts (plain numpy dataclasses)
  container      header, section table, generic section body (build / validate / map)
  *_section(s)   encode/decode per section kind (scene, mesh, skeleton, voxel)
  writer/reader  write_gfg / read_gfg
  mesh_build     Blender-style per-corner arrays ↔ single-indexed GFG meshes
  transforms     node TRS → world matrices
  voxel_set      CacheBuildResult ↔ VoxelSet
  cli            the ``info`` / ``verify`` command-line tools (``python -m voxgi_addon.files.gfg``)
"""
from .errors import GFGError
from .mesh_build import MeshArrays, VertexTypes, build_mesh, canonical_skin, mesh_arrays
from .model import (
    Animation,
    GFGScene,
    Material,
    MaterialRange,
    Mesh,
    Node,
    Pose,
    ProbeGrid,
    RawSection,
    Skeleton,
    VertexComponent,
    VoxelSet,
)
from .reader import read_gfg, verify_checksums
from .transforms import compose_world
from .voxel_set import voxel_set_from_result, voxel_set_to_result
from .writer import to_bytes, write_gfg

__all__ = [
    "GFGError", "GFGScene", "Node", "Pose", "Mesh", "VertexComponent", "MaterialRange", "Material",
    "Skeleton", "Animation", "VoxelSet", "ProbeGrid", "RawSection", "MeshArrays", "VertexTypes",
    "build_mesh", "canonical_skin", "mesh_arrays", "read_gfg", "verify_checksums", "write_gfg",
    "to_bytes", "compose_world", "voxel_set_from_result", "voxel_set_to_result",
]

"""Read a GFG file into a ``GFGScene`` whose arrays are views into the file (no copies).

``read_gfg`` validates the header, the section table, every section's checksum and every
count, offset, size and cross-reference before it maps an array, and raises ``GFGError``
(naming the section and field) for anything wrong. Sections of unknown kinds are skipped
(recorded in ``GFGScene.skipped_sections``) unless flagged REQUIRED.
"""
from __future__ import annotations

import mmap
import os

from .container import Header, SectionView, check_crc, kind_name, parse_header
from .errors import GFGError
from .mesh_section import decode_mesh
from .model import GFGScene, SkippedSection
from .scene_sections import StringView, decode_materials, decode_nodes
from .skeleton_sections import decode_animation, decode_skeleton
from .spec import KNOWN_KINDS, SECTION_REQUIRED, SINGLETON_KINDS, Kind, NodeKind
from .voxel_sections import decode_probe_grid, decode_voxel_cache, decode_voxel_set


def open_buffer(source) -> memoryview:
    """A read-only memoryview of ``source``: a path (memory-mapped), bytes-like or mmap."""
    if isinstance(source, (str, os.PathLike)):
        with open(os.fspath(source), "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size == 0:
                raise GFGError("header", "file size", "the file is empty")
            return memoryview(mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ))
    view = memoryview(source)
    return view.cast("B") if view.format != "B" or view.ndim != 1 else view


def read_header(source) -> tuple[memoryview, Header]:
    buf = open_buffer(source)
    return buf, parse_header(buf)


def _by_kind(buf, header: Header, verify: bool, scene: GFGScene) -> dict[bytes, list[SectionView]]:
    views: dict[bytes, list[SectionView]] = {k: [] for k in KNOWN_KINDS}
    for entry in header.sections:
        where = f"section {entry.index} {kind_name(entry.kind)}"
        if verify:
            check_crc(buf, entry, where)
        if entry.kind not in views:
            if entry.flags & SECTION_REQUIRED:
                raise GFGError(where, "flags", f"kind {entry.kind!r} is required but unknown to this reader")
            scene.skipped_sections.append(SkippedSection(entry.index, entry.kind, entry.size))
            continue
        views[entry.kind].append(SectionView(buf, entry, header.zero_padding))
    for kind in SINGLETON_KINDS:
        if len(views[kind]) > 1:
            raise GFGError(f"section {views[kind][1].entry.index} {kind_name(kind)}", "kind",
                           "this kind may appear once per file")
    return views


def read_gfg(source, *, verify: bool = True) -> GFGScene:
    """Read a GFG file.

    source : path (memory-mapped), bytes, bytearray, memoryview or mmap.
    verify : check every section's CRC-32 first (the header and table are always checked, and
        so, from format 1.1, is every padding and reserved byte).
    Returns a GFGScene whose arrays are read-only views into the source buffer.
    Raises GFGError for any malformed input.
    """
    buf, header = read_header(source)
    scene = GFGScene(version=header.version)
    views = _by_kind(buf, header, verify, scene)
    strings = StringView(views[Kind.STRINGS][0] if views[Kind.STRINGS] else None)
    if views[Kind.MATERIALS]:
        scene.materials = decode_materials(views[Kind.MATERIALS][0], strings)
    scene.skeletons = [decode_skeleton(v, strings) for v in views[Kind.SKELETON]]
    bone_counts = [s.bone_count for s in scene.skeletons]
    scene.meshes = [decode_mesh(v, strings, len(scene.materials), bone_counts)
                    for v in views[Kind.MESH]]
    if views[Kind.NODES]:
        scene.nodes = decode_nodes(views[Kind.NODES][0], strings, len(scene.meshes), bone_counts)
    for i, node in enumerate(scene.nodes):
        if node.kind == NodeKind.MESH and scene.meshes[node.mesh].skeleton >= 0 and node.armature_node >= 0 \
                and scene.nodes[node.armature_node].skeleton != scene.meshes[node.mesh].skeleton:
            raise GFGError(f"section {views[Kind.NODES][0].entry.index} NODE", f"node {i} armature_node",
                           "its skeleton is not the one the mesh's bone indices refer to")
    node_kinds = [(n.kind, n.skeleton) for n in scene.nodes]
    scene.animations = [decode_animation(v, strings, bone_counts, node_kinds)
                        for v in views[Kind.ANIMATION]]
    if views[Kind.VOXEL_SET]:
        scene.voxels = decode_voxel_set(views[Kind.VOXEL_SET][0], strings)
    keys = frozenset(scene.voxels.keys) if scene.voxels is not None else frozenset()
    caches = [decode_voxel_cache(v, strings, scene.voxels, keys) for v in views[Kind.VOXEL_CACHE]]
    seen = set()
    for v, cache in zip(views[Kind.VOXEL_CACHE], caches):
        if (cache.key, cache.cascade) in seen:
            v.fail("info.key/cascade", f"a second cache for '{cache.key}' cascade {cache.cascade}")
        seen.add((cache.key, cache.cascade))
    if scene.voxels is not None:
        scene.voxels.caches = caches
    scene.probe_grids = [decode_probe_grid(v) for v in views[Kind.PROBE_GRID]]
    return scene


def verify_checksums(source) -> list[str]:
    """Every section whose CRC-32 is wrong, as messages (header/table errors raise GFGError)."""
    buf, header = read_header(source)
    problems = []
    for entry in header.sections:
        try:
            check_crc(buf, entry, f"section {entry.index} {kind_name(entry.kind)}")
        except GFGError as error:
            problems.append(str(error))
    return problems

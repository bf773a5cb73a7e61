"""Write a ``GFGScene`` as a GFG file (see ``docs/gfg.md``).

Sections are written in a fixed order (STRG, NODE, MATL, MESH…, SKEL…, ANIM…, VXST, VOXC…,
PRBG…, then extra sections), so the same scene always gives the same bytes. Arrays are
written straight from their numpy buffers (no copies except interleaving vertex blocks).
"""
from __future__ import annotations

import io
import os

from .container import SectionBuilder, write_container
from .errors import GFGError
from .mesh_section import encode_mesh
from .model import GFGScene, RawSection
from .scene_sections import StringTable, encode_materials, encode_nodes
from .skeleton_sections import encode_animation, encode_skeleton
from .spec import KNOWN_KINDS
from .voxel_sections import encode_probe_grid, encode_voxel_cache, encode_voxel_set


class _RawBuilder:
    def __init__(self, raw: RawSection):
        if len(raw.kind) != 4 or raw.kind in KNOWN_KINDS:
            raise GFGError("extra section", "kind", f"{raw.kind!r} is not a new four-byte kind")
        self.kind, self.flags, self.version, self.payload = raw.kind, raw.flags, raw.version, raw.payload

    def build(self):
        return [self.payload], len(self.payload)


def build_sections(scene: GFGScene) -> list[SectionBuilder]:
    """The sections of ``scene`` in file order (STRG first)."""
    strings = StringTable()
    body = [encode_nodes(scene.nodes, strings), encode_materials(scene.materials, strings)]
    body += [encode_mesh(m, strings) for m in scene.meshes]
    body += [encode_skeleton(s, strings) for s in scene.skeletons]
    body += [encode_animation(a, strings) for a in scene.animations]
    if scene.voxels is not None:
        body.append(encode_voxel_set(scene.voxels, strings))
        body += [encode_voxel_cache(c, strings) for c in scene.voxels.caches]
    body += [encode_probe_grid(g) for g in scene.probe_grids]
    body += [_RawBuilder(r) for r in scene.extra_sections]
    return [strings.section(), *body]


def write_gfg(target, scene: GFGScene) -> int:
    """Write ``scene`` to ``target`` (a path or a binary stream); return the number of bytes.

    Raises GFGError when the scene cannot be represented (wrong storage dtype of a vertex
    component, indices that are not unsigned, ...).
    """
    sections = build_sections(scene)
    if hasattr(target, "write"):
        return write_container(target, sections)
    with open(os.fspath(target), "wb") as stream:
        return write_container(stream, sections)


def to_bytes(scene: GFGScene) -> bytes:
    """The file's bytes in memory."""
    stream = io.BytesIO()
    write_gfg(stream, scene)
    return stream.getvalue()

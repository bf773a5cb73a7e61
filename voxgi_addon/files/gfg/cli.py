"""``python -m voxgi_addon.files.gfg info FILE`` / ``verify FILE``: inspect and check GFG files."""
from __future__ import annotations

import argparse
import sys

import numpy as np

from . import data_types as dtypes
from .container import kind_name
from .errors import GFGError
from .model import GFGScene
from .reader import read_gfg, read_header, verify_checksums
from .spec import Kind, Logic, NodeKind


def _mesh_line(mesh) -> str:
    parts = ", ".join(f"{Logic.NAMES[c.logic] if c.logic < len(Logic.NAMES) else c.logic} "
                      f"{dtypes.name_of(c.data_type)}" for c in mesh.components)
    index = "non-indexed" if mesh.indices is None else f"{len(mesh.indices)} indices ({mesh.indices.dtype.name})"
    layout = "interleaved" if mesh.interleaved else "separate blocks"
    skin = f", skeleton {mesh.skeleton}" if mesh.skeleton >= 0 else ""
    return (f"'{mesh.name}': {mesh.vertex_count} vertices, {index}, {len(mesh.ranges)} material "
            f"ranges{skin}; {parts} ({layout})")


def _contents(scene: GFGScene) -> dict[bytes, list[str]]:
    """One description per section of each known kind, in file order."""
    kinds = [NodeKind.NAMES[n.kind] for n in scene.nodes]
    counts = ", ".join(f"{kinds.count(k)} {k}" for k in NodeKind.NAMES if kinds.count(k))
    posed = sum(n.pose is not None for n in scene.nodes)
    voxels = scene.voxels
    return {
        Kind.STRINGS: ["strings"],
        Kind.NODES: [f"{len(scene.nodes)} nodes ({counts or 'none'}), {posed} posed armatures"],
        Kind.MATERIALS: [f"{len(scene.materials)} materials: "
                         + ", ".join(f"'{m.name}'" for m in scene.materials)],
        Kind.MESH: [_mesh_line(m) for m in scene.meshes],
        Kind.SKELETON: [f"'{s.name}': {s.bone_count} bones" for s in scene.skeletons],
        Kind.ANIMATION: [f"'{a.name}': {len(a.times)} keys × {a.rotations.shape[1]} bones, skeleton "
                         f"{a.skeleton}{', hip translation' if a.hip_translations is not None else ''}"
                         for a in scene.animations],
        Kind.VOXEL_SET: [] if voxels is None else [
            f"base span {voxels.base_span:g} m, {voxels.cascade_count} cascades, {len(voxels.keys)} "
            f"meshes, {len(voxels.bindings)} bindings, {len(voxels.skipped)} skipped"],
        Kind.VOXEL_CACHE: [] if voxels is None else [
            f"'{c.key}' cascade {c.cascade} (span {c.span:g} m): {c.voxel_count} voxels"
            f"{', skinned' if c.skinned else ''}" for c in voxels.caches],
        Kind.PROBE_GRID: [_probe_line(g) for g in scene.probe_grids],
    }


def _probe_line(g) -> str:
    from ...probes.grid import memory_report

    flags = np.asarray(g.flags)
    memory = memory_report(g)
    masks = f"masks at {g.mask_threshold:.0%}" if g.mask_threshold > 0 else "no masks"
    return (f"{len(g.positions)} probes ({int((flags & 1).sum())} relocated, {int(((flags & 2) != 0).sum())} "
            f"disabled), {len(g.volume_cells)} active volumes of {'×'.join(str(int(d)) for d in g.dims)} "
            f"({'×'.join(f'{s:g}' for s in g.volume_size)} m), {masks}; SH index {memory['sh_index']} B, "
            f"SH {memory['sh_coefficients']} B, occlusion index {memory['occlusion_index']} B, "
            f"masks {memory['occlusion_masks']} B")


def info(path: str, out=print) -> int:
    try:
        _, header = read_header(path)
    except GFGError as error:
        out(f"{path}: {error}")
        return 1
    out(f"{path}: GFG {header.version[0]}.{header.version[1]}, {header.file_size} bytes, "
        f"{len(header.sections)} sections")
    problem = None
    try:
        contents = _contents(read_gfg(path, verify=False))
    except GFGError as error:
        contents, problem = {}, str(error)
    seen: dict[bytes, int] = {}
    out(f"{'#':>3}  kind  {'offset':>12}  {'size':>12}  crc32       contents")
    for e in header.sections:
        k = seen.get(e.kind, 0)
        seen[e.kind] = k + 1
        items = contents.get(e.kind)
        text = items[k] if items and k < len(items) else ("(skipped: unknown kind)" if items is None and
                                                          problem is None else "")
        out(f"{e.index:>3}  {kind_name(e.kind):4}  {e.offset:>12}  {e.size:>12}  0x{e.crc:08X}  {text}")
    if problem:
        out(f"cannot describe the contents: {problem}")
        return 1
    return 0


def verify(path: str, out=print) -> int:
    header = None
    try:
        _, header = read_header(path)
        problems = verify_checksums(path)
        if not problems:
            read_gfg(path, verify=False)
    except GFGError as error:
        problems = [str(error)]
    for p in problems:
        out(f"{path}: {p}")
    if not problems:
        if header.zero_padding:
            out(f"{path}: OK (every byte: header and section checksums, zero padding and reserved "
                "fields, counts, offsets and references checked)")
        else:
            out(f"{path}: OK (GFG {header.version[0]}.{header.version[1]}: header and section checksums, "
                "counts, offsets and references checked; this version's padding is not checked)")
    return 1 if problems else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m voxgi_addon.files.gfg", description=__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("info", help="print the sections, counts and sizes").add_argument("file")
    sub.add_parser("verify", help="check every checksum, padding byte and bound (exit 1 if any is "
                   "wrong)") \
        .add_argument("file")
    args = ap.parse_args(argv)
    try:
        return (info if args.command == "info" else verify)(args.file)
    except OSError as error:  # a missing or unreadable file: say so, no traceback
        print(f"{args.file}: cannot read: {error.strerror or error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

"""VXST, VOXC and PRBG sections: the voxel-cache set, one cache per (mesh, cascade), probe grids."""
from __future__ import annotations

import numpy as np

from ...probes.grid import CORNER_OFFSETS, NO_INDEX, index_arrays
from ...scene.snapshot import OBJECT_KINDS
from ...voxelize.cache import VoxelCache
from ...voxelize.packing import MAX_CELLS_PER_AXIS
from ...voxelize.scene_caches import ObjectBinding, SkippedMesh
from . import data_types as dtypes
from .container import SectionBuilder, SectionView
from .errors import GFGError
from .model import ProbeGrid, VoxelSet
from .scene_sections import StringTable, StringView, check_index
from .spec import (
    BINDING_RECORD,
    PROBE_FLAG_BITS,
    PROBE_GRID_INFO,
    PROBE_GRID_INFO_1_1,
    SH_L2_COEFFICIENTS,
    SKIPPED_RECORD,
    VOXEL_CACHE_INFO,
    VOXEL_CACHE_SKINNED,
    VOXEL_SET_INFO,
    Kind,
    Role,
)

U32, U64 = dtypes.code_of("UINT32_1"), dtypes.code_of("UINT64_1")
FLOAT3 = dtypes.code_of("FLOAT_3")
POSITION_WORD = dtypes.code_of("UINT_2_10_10_10")
NORMAL_WORD = dtypes.code_of("NORM8_4")
UNORM8X4 = dtypes.code_of("UNORM8_4")
UINT8X4 = dtypes.code_of("UINT8_4")
# (role, name, data type, VoxelCache attribute)
VOXEL_ARRAYS = (
    (Role.VOXEL_POSITIONS, "VOXEL_POSITIONS", POSITION_WORD, "positions"),
    (Role.VOXEL_NORMALS, "VOXEL_NORMALS", NORMAL_WORD, "normals"),
    (Role.VOXEL_COLORS, "VOXEL_COLORS", UNORM8X4, "colors"),
    (Role.VOXEL_WEIGHTS, "VOXEL_WEIGHTS", UNORM8X4, "weights"),
    (Role.VOXEL_BONE_INDICES, "VOXEL_BONE_INDICES", UINT8X4, "bone_indices"),
)


# ------------------------------------------------------------------ voxel set and caches

def encode_voxel_set(voxels: VoxelSet, strings: StringTable) -> SectionBuilder:
    bindings = np.zeros(len(voxels.bindings), BINDING_RECORD)
    for i, (name, b) in enumerate(voxels.bindings.items()):
        bindings[i] = (strings(name), strings(b.cache_key), OBJECT_KINDS.index(b.kind), 0,
                       np.asarray(b.rigid_matrix, np.float64))
    skipped = np.zeros(len(voxels.skipped), SKIPPED_RECORD)
    for i, s in enumerate(voxels.skipped):
        skipped[i] = (strings(s.mesh), s.cascade, s.span, s.dims, 0)
    info = np.array([(voxels.base_span, voxels.cascade_count, len(voxels.keys), len(bindings),
                      len(skipped))], VOXEL_SET_INFO)
    s = SectionBuilder(Kind.VOXEL_SET, info)
    s.add(Role.CACHE_KEYS, U32, np.array([strings(k) for k in voxels.keys], "<u4"))
    s.add(Role.BINDINGS, dtypes.RECORD, bindings, element_size=BINDING_RECORD.itemsize)
    s.add(Role.SKIPPED, dtypes.RECORD, skipped, element_size=SKIPPED_RECORD.itemsize)
    return s


def encode_voxel_cache(cache: VoxelCache, strings: StringTable) -> SectionBuilder:
    flags = VOXEL_CACHE_SKINNED if cache.skinned else 0
    info = np.array([(strings(cache.key), cache.cascade, cache.span, cache.origin_cell, cache.dims,
                      cache.voxel_count, flags, 0)], VOXEL_CACHE_INFO)
    s = SectionBuilder(Kind.VOXEL_CACHE, info)
    for role, name, code, attribute in VOXEL_ARRAYS:
        words = getattr(cache, attribute)
        if words is None:
            continue
        words = np.asarray(words)
        if words.shape != (cache.voxel_count,) or words.dtype.kind != "u" or words.dtype.itemsize != 4:
            raise GFGError(f"voxel cache '{cache.key}' cascade {cache.cascade}", attribute,
                           f"{words.dtype}{words.shape} is not ({cache.voxel_count},) uint32 words")
        s.add(role, code, words.astype("<u4", copy=False))
    return s


def decode_voxel_set(view: SectionView, strings: StringView) -> VoxelSet:
    info = view.info(VOXEL_SET_INFO)
    cascades = int(info["cascade_count"])
    base_span = float(info["base_span"])
    if not (np.isfinite(base_span) and base_span > 0):
        view.fail("info.base_span", f"{base_span} is not a positive number of metres")
    keys = view.array(Role.CACHE_KEYS, "CACHE_KEYS", (U32,), int(info["key_count"]))
    bindings = view.array(Role.BINDINGS, "BINDINGS", (dtypes.RECORD,), int(info["binding_count"]),
                          record=BINDING_RECORD)
    skipped = view.array(Role.SKIPPED, "SKIPPED", (dtypes.RECORD,), int(info["skipped_count"]),
                         record=SKIPPED_RECORD)
    key_list = [strings.get(k, view, f"cache key {i}") for i, k in enumerate(keys)]
    if len(set(key_list)) != len(key_list):
        view.fail("array CACHE_KEYS", "a key appears twice")
    result = VoxelSet(base_span, cascades, key_list, [])
    for i, b in enumerate(bindings):
        kind = check_index(view, f"binding {i} kind", b["kind"], len(OBJECT_KINDS))
        result.bindings[strings.get(b["object"], view, f"binding {i} object")] = ObjectBinding(
            strings.get(b["cache_key"], view, f"binding {i} cache_key"), b["rigid_matrix"],
            OBJECT_KINDS[kind])
    for i, r in enumerate(skipped):
        check_index(view, f"skipped {i} cascade", r["cascade"], cascades)
        result.skipped.append(SkippedMesh(strings.get(r["mesh"], view, f"skipped {i} mesh"),
                                          int(r["cascade"]), float(r["span"]),
                                          tuple(int(d) for d in r["dims"])))
    return result


def decode_voxel_cache(view: SectionView, strings: StringView, voxels: VoxelSet | None,
                       keys: frozenset) -> VoxelCache:
    """keys : ``voxels.keys`` as a set (so that reading many caches stays linear)."""
    info = view.info(VOXEL_CACHE_INFO)
    key = strings.get(info["key"], view, "info.key")
    view.name_as(f"{key} @ cascade {int(info['cascade'])}")
    if voxels is None:
        view.fail("kind", "a voxel cache needs the file's VXST section")
    if key not in keys:
        view.fail("info.key", f"'{key}' is not in the voxel set's keys")
    cascade = check_index(view, "info.cascade", info["cascade"], voxels.cascade_count)
    dims = info["dims"].astype(np.int64)
    if (dims < 1).any() or (dims > MAX_CELLS_PER_AXIS).any():
        view.fail("info.dims", f"{dims.tolist()} is outside 1..{MAX_CELLS_PER_AXIS} cells per axis")
    span = float(info["span"])
    if not (np.isfinite(span) and span > 0):
        view.fail("info.span", f"{span} is not a positive number of metres")
    count = int(info["voxel_count"])
    skinned = bool(int(info["flags"]) & VOXEL_CACHE_SKINNED)
    words = {}
    for role, name, code, attribute in VOXEL_ARRAYS:
        required = attribute not in ("weights", "bone_indices") or skinned
        d = view.desc(role, name, required=required)
        if d is not None and not required:
            view.fail(f"array {name}", "present in a cache not flagged skinned")
        if d is not None:
            view.map(d, name, (code,), count)  # validates type, size and count
            words[attribute] = np.frombuffer(view.buf, "<u4", count, d.offset)
    return VoxelCache(key=key, cascade=cascade, span=span,
                      origin_cell=info["origin_cell"].astype(np.int64), dims=dims,
                      positions=words["positions"], normals=words["normals"], colors=words["colors"],
                      weights=words.get("weights"), bone_indices=words.get("bone_indices"))


# ------------------------------------------------------------------ probe grids

FLOAT1 = dtypes.code_of("FLOAT_1")
MAX_GRID_CORNERS = 1 << 28  # (X+1)(Y+1)(Z+1) beyond this is not a probe grid anyone bakes


def encode_probe_grid(grid: ProbeGrid) -> SectionBuilder:
    """A PRBG section in the 1.2 layout (docs/gfg.md "PRBG")."""
    p, v = len(grid.positions), len(grid.volume_cells)
    size = np.asarray(grid.volume_size, np.float64)
    info = np.zeros(1, PROBE_GRID_INFO)
    info[0] = (grid.origin, size[0], grid.dims, p, v, SH_L2_COEFFICIENTS, size,
               grid.mask_threshold, 0)
    s = SectionBuilder(Kind.PROBE_GRID, info)
    s.add(Role.PROBE_POSITIONS, FLOAT3, np.asarray(grid.positions, "<f4").reshape(p, 3))
    s.add(Role.PROBE_SH, FLOAT3, np.asarray(grid.sh, "<f4").reshape(p * SH_L2_COEFFICIENTS, 3))
    s.add(Role.VOLUME_CELLS, U32, np.asarray(grid.volume_cells, "<u4").reshape(v))
    s.add(Role.VOLUME_PROBES, U32, np.asarray(grid.volume_probes, "<u4").reshape(v * 8))
    s.add(Role.VOLUME_MASKS, U64, np.asarray(grid.volume_masks, "<u8").reshape(v * 8))
    s.add(Role.SH_INDEX, U32, np.asarray(grid.sh_index, "<u4").ravel())
    s.add(Role.MASK_INDEX, U32, np.asarray(grid.mask_index, "<u4").ravel())
    s.add(Role.PROBE_VALIDITY, FLOAT1, np.asarray(grid.validity, "<f4").reshape(p))
    s.add(Role.PROBE_FLAGS, U32, np.asarray(grid.flags, "<u4").reshape(p))
    return s


def _check_index(view: SectionView, name: str, stored, expected) -> None:
    if not np.array_equal(stored, expected):
        k = int(np.argmax(stored != expected))
        view.fail(f"array {name}", f"entry {k} is {int(stored[k])}, the volumes say {int(expected[k])}")


def decode_probe_grid(view: SectionView) -> ProbeGrid:
    """A PRBG section of format 1.0–1.2 (1.0/1.1: cubic volumes, index arrays rebuilt)."""
    newer = view.info_size >= PROBE_GRID_INFO.itemsize
    info = view.info(PROBE_GRID_INFO if newer else PROBE_GRID_INFO_1_1)
    p, v = int(info["probe_count"]), int(info["volume_count"])
    if int(info["sh_coefficients"]) != SH_L2_COEFFICIENTS:
        view.fail("info.sh_coefficients", f"{int(info['sh_coefficients'])} is not 9 (SH L2)")
    dims = info["dims"].astype(np.int64)
    if (dims < 1).any() or int((dims + 1).prod()) > MAX_GRID_CORNERS:
        view.fail("info.dims", f"{dims.tolist()} is not a probe grid's volume count")
    cells = int(dims.prod())
    size = np.asarray(info["volume_size"] if newer else [info["cell_size"]] * 3, np.float64)
    if not (np.isfinite(size).all() and (size > 0).all()) or float(info["cell_size"]) != size[0]:
        view.fail("info.volume_size", f"{size.tolist()} (cell size {float(info['cell_size'])}) is not "
                  "a positive volume size whose x is the cell size")
    if not np.isfinite(info["origin"]).all():
        view.fail("info.origin", "is not finite")
    threshold = float(info["mask_threshold"]) if newer else 0.5
    if not 0.0 <= threshold <= 1.0:
        view.fail("info.mask_threshold", f"{threshold} is not a share in [0, 1]")
    positions = view.array(Role.PROBE_POSITIONS, "PROBE_POSITIONS", (FLOAT3,), p)
    sh = view.array(Role.PROBE_SH, "PROBE_SH", (FLOAT3,), p * SH_L2_COEFFICIENTS)
    volume_cells = view.array(Role.VOLUME_CELLS, "VOLUME_CELLS", (U32,), v)
    probes = view.array(Role.VOLUME_PROBES, "VOLUME_PROBES", (U32,), 8 * v)
    masks = view.array(Role.VOLUME_MASKS, "VOLUME_MASKS", (U64,), 8 * v)
    if v and int(volume_cells.max()) >= cells:
        view.fail("array VOLUME_CELLS", f"cell {int(volume_cells.max())} is outside the {cells} cells")
    if v and int(probes.max()) >= p:
        view.fail("array VOLUME_PROBES", f"probe {int(probes.max())} is not one of the {p} probes")
    optional = dict(sh_index=None, mask_index=None, validity=None, flags=None)
    if newer:
        if v > 1 and not (np.diff(volume_cells.astype(np.int64)) > 0).all():
            view.fail("array VOLUME_CELLS", "cells are not strictly ascending")
        sh_index = view.array(Role.SH_INDEX, "SH_INDEX", (U32,), int((dims + 1).prod()))
        mask_index = view.array(Role.MASK_INDEX, "MASK_INDEX", (U32,), cells)
        validity = view.array(Role.PROBE_VALIDITY, "PROBE_VALIDITY", (FLOAT1,), p)
        flags = view.array(Role.PROBE_FLAGS, "PROBE_FLAGS", (U32,), p)
        want_sh, want_mask = index_arrays(dims, volume_cells, probes.reshape(v, 8))
        _check_index(view, "SH_INDEX", sh_index, want_sh)
        _check_index(view, "MASK_INDEX", mask_index, want_mask)
        # Shared corners name one probe: every volume's corner agrees with the SH index.
        seen = want_sh[_corner_cells(dims, volume_cells)].ravel()
        _check_index(view, "VOLUME_PROBES", probes.astype(np.int64), seen.astype(np.int64))
        used = want_sh[want_sh != NO_INDEX]
        if len(np.unique(used)) != len(used):
            view.fail("array VOLUME_PROBES", "one probe sits at two grid corners")
        if not (np.isfinite(validity) & (validity >= 0) & (validity <= 1)).all():
            view.fail("array PROBE_VALIDITY", "a value is not a share in [0, 1]")
        if (flags & ~np.uint32(PROBE_FLAG_BITS)).any():
            k = int(np.argmax(flags & ~np.uint32(PROBE_FLAG_BITS)))
            view.fail("array PROBE_FLAGS", f"probe {k} has undefined flag bits {int(flags[k]):#x}")
        optional = dict(sh_index=sh_index, mask_index=mask_index, validity=validity, flags=flags)
    return ProbeGrid(info["origin"], size, dims, positions, sh.reshape(p, SH_L2_COEFFICIENTS, 3),
                     volume_cells, probes.reshape(v, 8), masks.reshape(v, 8),
                     mask_threshold=threshold, **optional)


def _corner_cells(dims, volume_cells) -> np.ndarray:
    """(V, 8) linear grid corners of each volume (``probes.grid.CORNER_OFFSETS`` order)."""
    c = np.asarray(volume_cells, np.int64)
    xyz = np.stack([c % dims[0], (c // dims[0]) % dims[1], c // (dims[0] * dims[1])], axis=1)
    xyz = xyz[:, None, :] + CORNER_OFFSETS[None]
    return xyz[..., 0] + (dims[0] + 1) * (xyz[..., 1] + (dims[1] + 1) * xyz[..., 2])

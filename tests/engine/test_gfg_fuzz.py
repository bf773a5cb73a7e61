"""Fuzzing the GFG reader: truncated, bit-flipped, overwritten and size-inflated files only ever
raise GFGError, never hang, and never allocate more than a small multiple of the file's size.

Plain corruption is caught by the checksums, so most strategies also *reseal* the file (recompute
every CRC) to drive the damage past them into the structural checks. 3,900 cases in total; the
allocation bound is measured with tracemalloc on 300 of them (tracing slows reads ~10x).

Then every byte of the file is labelled (header, section table, padding, section padding,
reserved fields, each kind's payload) and each class is damaged without resealing: no damaged
file may read, and `verify` must say so; padding and reserved bytes are also damaged one at a
time with the checksums resealed, which only the zero rule can catch (docs/gfg.md, "Every byte
is checked").
"""
import contextlib
import io
import pathlib
import struct
import subprocess
import sys
import tracemalloc
import zlib

import numpy as np
import pytest
from gfg_scenes import full_scene
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from voxgi.voxgi_addon.files.gfg import GFGError, GFGScene, Material, read_gfg, to_bytes
from voxgi.voxgi_addon.files.gfg import data_types as dtypes
from voxgi.voxgi_addon.files.gfg.cli import main as cli_main
from voxgi.voxgi_addon.files.gfg.spec import (
    ARRAY_DESC,
    BINDING_RECORD,
    COMPONENT_RECORD,
    FILE_HEADER,
    KNOWN_KINDS,
    MATERIAL_RECORD,
    MATERIALS_INFO,
    NODE_RECORD,
    PROBE_GRID_INFO,
    RANGE_RECORD,
    SECTION_ENTRY,
    SECTION_PRELUDE,
    SKIPPED_RECORD,
    STRINGS_INFO,
    TEXTURE_RECORD,
    VOXEL_CACHE_INFO,
    Kind,
    Role,
)

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
BASE = to_bytes(full_scene(voxels_per_cache=8))
SIZE = len(BASE)
# A read may build Python objects per record (names, nodes): allow a few times the file size.
ALLOCATION_LIMIT = 8 * SIZE + 256 * 1024
# The deadline only catches hangs (a case normally takes milliseconds), so it is generous.
FUZZ = settings(deadline=10_000, database=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def reseal(data: bytearray) -> bytearray:
    """Recompute every checksum that the (possibly damaged) header and table let us find."""
    if len(data) < 64:
        return data
    count, table_offset = struct.unpack_from("<I", data, 32)[0], struct.unpack_from("<Q", data, 24)[0]
    if table_offset + 32 * count <= len(data):
        for i in range(count):
            at = table_offset + 32 * i
            offset, size = struct.unpack_from("<QQ", data, at + 8)
            if offset + size <= len(data):
                struct.pack_into("<I", data, at + 24, zlib.crc32(bytes(data[offset:offset + size])))
        struct.pack_into("<I", data, 36, zlib.crc32(bytes(data[table_offset:table_offset + 32 * count])))
    struct.pack_into("<I", data, 60, zlib.crc32(bytes(data[:60])))
    return data


def _structural_words() -> list[int]:
    """Byte offsets of every 4-byte word in the header, table, section preludes, info structs,
    array tables and record arrays: where counts, offsets, sizes and references live."""
    words = list(range(0, 64 + 32 * struct.unpack_from("<I", BASE, 32)[0], 4))
    for entry in np.frombuffer(BASE, SECTION_ENTRY, struct.unpack_from("<I", BASE, 32)[0], 64):
        start = int(entry["offset"])
        if bytes(entry["kind"]) not in KNOWN_KINDS:
            continue
        prelude = np.frombuffer(BASE, SECTION_PRELUDE, 1, start)[0]
        table = start + int(prelude["array_table_offset"])
        descs = np.frombuffer(BASE, ARRAY_DESC, int(prelude["array_count"]), table)
        words += range(start, table + 32 * len(descs), 4)
        for d in descs:
            if int(d["data_type"]) == 1000:  # RECORD
                first = start + int(d["offset"])
                words += range(first, first + int(d["count"]) * int(d["element_size"]), 4)
    return words


WORDS = _structural_words()
BIG = st.sampled_from([SIZE, SIZE + 1, 2**31 - 1, 2**31, 2**32 - 1, 2**40, 2**63, 2**64 - 1])


def check_reader(data: bytes) -> None:
    """Only GFGError may come out of a read (or of writing back what was read)."""
    try:
        scene = read_gfg(data)
    except GFGError:
        return
    try:
        to_bytes(scene)
    except GFGError:
        pass


def inflate(data: bytearray, fields) -> bytearray:
    for at, value, wide in fields:
        if wide and at + 8 <= SIZE:
            struct.pack_into("<Q", data, at, value)
        else:
            struct.pack_into("<I", data, at, value & 0xFFFFFFFF)
    return reseal(data)


def test_the_unmodified_file_reads():
    assert len(read_gfg(BASE).meshes) == 4
    assert len(WORDS) > 500


@settings(FUZZ, max_examples=500)
@given(length=st.integers(0, SIZE - 1), reseal_it=st.booleans())
def test_truncated_files(length, reseal_it):
    data = bytearray(BASE[:length])
    if reseal_it and length >= 64:
        struct.pack_into("<Q", data, 16, length)  # claim the truncated size, so sections are hit
        reseal(data)
    check_reader(bytes(data))


@settings(FUZZ, max_examples=700)
@given(flips=st.lists(st.tuples(st.integers(0, SIZE - 1), st.integers(0, 7)), min_size=1, max_size=8),
       reseal_it=st.booleans())
def test_bit_flipped_files(flips, reseal_it):
    data = bytearray(BASE)
    for at, bit in flips:
        data[at] ^= 1 << bit
    check_reader(bytes(reseal(data) if reseal_it else data))


@settings(FUZZ, max_examples=900)
@given(fields=st.lists(st.tuples(st.sampled_from(WORDS), BIG, st.booleans()), min_size=1, max_size=3))
def test_size_inflated_files(fields):
    """Counts, offsets and sizes set to huge values (and the checksums made to match)."""
    check_reader(bytes(inflate(bytearray(BASE), fields)))


@settings(FUZZ, max_examples=900)
@given(edits=st.lists(st.tuples(st.sampled_from(WORDS), st.integers(-3, 3)), min_size=1, max_size=4))
def test_nudged_structural_fields(edits):
    """Small off-by-a-few changes to structural words: the subtle ones a bound check must catch."""
    data = bytearray(BASE)
    for at, delta in edits:
        value = struct.unpack_from("<I", data, at)[0]
        struct.pack_into("<I", data, at, (value + delta) & 0xFFFFFFFF)
    check_reader(bytes(reseal(data)))


@settings(FUZZ, max_examples=600)
@given(start=st.integers(0, SIZE - 1), junk=st.binary(min_size=1, max_size=64),
       tail=st.binary(max_size=200))
def test_overwritten_and_extended_files(start, junk, tail):
    data = bytearray(BASE)
    data[start:start + len(junk)] = junk
    data += tail
    if tail:
        struct.pack_into("<Q", data, 16, len(data))
    check_reader(bytes(reseal(data)))


def test_material_ranges_claiming_every_entry_are_refused_at_the_first_bad_range():
    """20,000 materials each claiming all 20,000 uniforms would be 4·10⁸ steps: the reader
    refuses at material 1 (the message names it), not after checking every pair."""
    count = 20_000
    data = bytearray(to_bytes(GFGScene(materials=[Material(f"m{i}", 4, {0: np.float32([i])})
                                                  for i in range(count)])))
    header = np.frombuffer(data, SECTION_ENTRY, 3, 64)
    start = int(header[2]["offset"])  # STRG, NODE, MATL
    prelude = np.frombuffer(data, SECTION_PRELUDE, 1, start)[0]
    desc = np.frombuffer(data, ARRAY_DESC, 1, start + int(prelude["array_table_offset"]))[0]
    records = np.frombuffer(data, MATERIAL_RECORD, count, start + int(desc["offset"]))
    records["uniform_start"], records["uniform_count"] = 0, count
    with pytest.raises(GFGError, match=r"material 1 uniforms: \[0, 20000\) does not continue at entry 20000"):
        read_gfg(bytes(reseal(data)))


@pytest.fixture()
def traced():
    """Tracing for one test only (at module scope it would slow every later test ~10x)."""
    tracemalloc.start()
    yield
    tracemalloc.stop()


@settings(FUZZ, max_examples=300,
          suppress_health_check=[*FUZZ.suppress_health_check, HealthCheck.function_scoped_fixture])
@given(fields=st.lists(st.tuples(st.sampled_from(WORDS), BIG, st.booleans()), min_size=1, max_size=3),
       length=st.integers(64, SIZE))
def test_reads_allocate_no_more_than_the_file_justifies(traced, fields, length):
    """Traced separately (tracemalloc slows every allocation ~10x): inflated, then truncated."""
    data = inflate(bytearray(BASE), fields)[:length]
    struct.pack_into("<Q", data, 16, length)
    data = bytes(reseal(data))
    tracemalloc.reset_peak()
    before, _ = tracemalloc.get_traced_memory()
    check_reader(data)
    _, peak = tracemalloc.get_traced_memory()
    assert peak - before < ALLOCATION_LIMIT, f"read allocated {peak - before} bytes for a {len(data)}-byte file"


# ------------------------------------------------------------------ every byte is checked
# docs/gfg.md, "Every byte is checked": the header and table CRCs, the section CRCs and the
# zero padding and reserved fields together leave no byte of a file unverified. The map below
# labels every byte of BASE from the format's layout (parsed here with struct/numpy, not with
# the reader), then each class is damaged on its own.

INFO_STRUCTS = {Kind.STRINGS: STRINGS_INFO, Kind.MATERIALS: MATERIALS_INFO, Kind.VOXEL_CACHE: VOXEL_CACHE_INFO,
                Kind.PROBE_GRID: PROBE_GRID_INFO}
# PRBG arrays with classes of their own: the volume list and Bowald's index arrays restate each
# other (any change is refused even with the checksums resealed), and the probe flags.
PROBE_INDEX_ROLES = (Role.VOLUME_CELLS, Role.VOLUME_PROBES, Role.SH_INDEX, Role.MASK_INDEX)
RECORD_STRUCTS = {(Kind.NODES, Role.NODES): NODE_RECORD, (Kind.MATERIALS, Role.TEXTURES): TEXTURE_RECORD,
                  (Kind.MESH, Role.RANGES): RANGE_RECORD, (Kind.VOXEL_SET, Role.BINDINGS): BINDING_RECORD,
                  (Kind.VOXEL_SET, Role.SKIPPED): SKIPPED_RECORD, (Kind.MESH, Role.COMPONENTS): COMPONENT_RECORD}
HEADER_RESERVED = ("flags", "alignment", "reserved")  # fixed values: 0, 64, 0


class ByteMap:
    """A class name for every byte offset; ``hits`` counts how many times each byte was labelled."""

    def __init__(self, data: bytes):
        self.names: list[str] = []
        self.label = np.full(len(data), -1, np.int32)
        self.hits = np.zeros(len(data), np.int32)

    def mark(self, name: str, where) -> None:
        """Label ``where`` (a slice or an index array) as ``name``."""
        if name not in self.names:
            self.names.append(name)
        self.label[where] = self.names.index(name)
        self.hits[where] += 1

    def struct(self, name: str, at: int, dtype: np.dtype, count: int = 1, reserved=("reserved",)) -> None:
        """Label ``count`` structs at ``at`` field by field; reserved fields get their own class."""
        for field in dtype.names:
            sub, offset = dtype.fields[field][:2]
            starts = at + offset + dtype.itemsize * np.arange(count)
            self.mark("reserved" if field in reserved else name,
                      (starts[:, None] + np.arange(sub.itemsize)).reshape(-1))

    def offsets(self, name: str) -> np.ndarray:
        return np.flatnonzero(self.label == self.names.index(name))


def byte_map(data: bytes) -> ByteMap:
    m = ByteMap(data)
    count, table_offset = struct.unpack_from("<I", data, 32)[0], struct.unpack_from("<Q", data, 24)[0]
    m.struct("header", 0, FILE_HEADER, reserved=HEADER_RESERVED)
    m.mark("padding", slice(FILE_HEADER.itemsize, table_offset))
    m.struct("section table", table_offset, SECTION_ENTRY, count)
    previous = table_offset + SECTION_ENTRY.itemsize * count
    for entry in np.frombuffer(data, SECTION_ENTRY, count, table_offset):
        kind, start, size = bytes(entry["kind"]), int(entry["offset"]), int(entry["size"])
        m.mark("padding", slice(previous, start))
        previous = start + size
        payload = f"{kind.decode()} payload"
        if kind not in KNOWN_KINDS:
            m.mark(payload, slice(start, start + size))
            continue
        m.struct(payload, start, SECTION_PRELUDE)
        prelude = np.frombuffer(data, SECTION_PRELUDE, 1, start)[0]
        info_end = start + SECTION_PRELUDE.itemsize + int(prelude["info_size"])
        if kind in INFO_STRUCTS:
            m.struct(payload, start + SECTION_PRELUDE.itemsize, INFO_STRUCTS[kind])
        else:
            m.mark(payload, slice(start + SECTION_PRELUDE.itemsize, info_end))
        table = start + int(prelude["array_table_offset"])
        m.mark("section padding", slice(info_end, table))
        descs = np.frombuffer(data, ARRAY_DESC, int(prelude["array_count"]), table)
        m.struct(payload, table, ARRAY_DESC, len(descs))
        end = table + ARRAY_DESC.itemsize * len(descs)
        components, blocks = None, []
        for d in sorted(descs, key=lambda d: int(d["offset"])):
            role, at = int(d["role"]), start + int(d["offset"])
            m.mark("section padding", slice(end, at))
            end = at + int(d["count"]) * int(d["element_size"])
            if (kind, role) in RECORD_STRUCTS:
                m.struct(payload, at, RECORD_STRUCTS[kind, role], int(d["count"]))
            elif kind == Kind.MESH and role == Role.VERTEX_BLOCK:
                blocks.append(d)
            elif kind == Kind.PROBE_GRID and role in PROBE_INDEX_ROLES:
                m.mark("PRBG index", slice(at, end))
            elif kind == Kind.PROBE_GRID and role == Role.PROBE_FLAGS:
                m.mark("PRBG flags", slice(at, end))
            else:
                m.mark(payload, slice(at, end))
            if kind == Kind.MESH and role == Role.COMPONENTS:
                components = np.frombuffer(data, COMPONENT_RECORD, int(d["count"]), at)
        m.mark("section padding", slice(end, start + size))
        blocks.sort(key=lambda d: [int(e["offset"]) for e in descs].index(int(d["offset"])))  # table order
        for k, d in enumerate(blocks):  # vertex bytes that no component covers: stride padding
            stride, at = int(d["element_size"]), start + int(d["offset"])
            used = np.zeros(stride, bool)
            for c in components[components["block"] == k]:
                used[int(c["offset"]):int(c["offset"]) + dtypes.data_type(int(c["data_type"])).size] = True
            for column in range(stride):
                m.mark(payload if used[column] else "section padding",
                       at + column + stride * np.arange(int(d["count"])))
    m.mark("padding", slice(previous, len(data)))
    return m


MAP = byte_map(BASE)
ZERO_CLASSES = ("padding", "section padding", "reserved")  # must be zero
EVERY_BYTE = ("padding", "reserved")  # damaged one byte at a time (section padding: below, resealed)
SAMPLES = 40  # offsets sampled from each of the other classes


def test_every_byte_of_the_file_belongs_to_exactly_one_class():
    assert np.array_equal(MAP.hits, np.ones(SIZE, np.int32)), \
        f"bytes in no class: {np.flatnonzero(MAP.hits == 0)[:20]}, in two: {np.flatnonzero(MAP.hits > 1)[:20]}"
    sizes = {name: len(MAP.offsets(name)) for name in MAP.names}
    kinds = {bytes(e["kind"]).decode() for e in np.frombuffer(BASE, SECTION_ENTRY, 15, 64)}
    assert kinds == {k.decode() for k in KNOWN_KINDS} | {"FUTR"}
    assert set(sizes) == {"header", "section table", *ZERO_CLASSES, *(f"{k} payload" for k in kinds),
                          "PRBG index", "PRBG flags"}
    assert sum(sizes.values()) == SIZE and min(sizes.values()) > 0
    assert sizes["header"] == 64 - 20 and sizes["section table"] == 15 * 28  # reserved words apart
    assert 8 < sizes["padding"] < 64 * 16 and sizes["section padding"] > 100  # with stride padding


def test_the_writer_leaves_padding_and_reserved_bytes_zero():
    data = np.frombuffer(BASE, np.uint8)
    assert not data[MAP.offsets("padding")].any() and not data[MAP.offsets("section padding")].any()
    reserved = MAP.offsets("reserved")
    assert list(reserved[data[reserved] != 0]) == [44]  # only the header's alignment, = 64
    assert struct.unpack_from("<I", BASE, 44)[0] == 64


def _corruptions(rng, name):
    """(offsets, new bytes) edits inside one class: each padding and reserved byte on its own, a
    sample of the others; a bit flipped, the byte overwritten, a run of up to 8 bytes overwritten."""
    pool = MAP.offsets(name)
    chosen = pool if name in EVERY_BYTE else rng.choice(pool, min(SAMPLES, len(pool)), replace=False)
    for at in map(int, chosen):
        yield [at], [BASE[at] ^ (1 << int(rng.integers(8)))]
        yield [at], [BASE[at] ^ int(rng.integers(1, 256))]
        if name not in EVERY_BYTE:
            run = [j for j in range(at, min(at + int(rng.integers(2, 9)), SIZE)) if MAP.label[j] == MAP.label[at]]
            yield run, [BASE[j] ^ int(rng.integers(1, 256)) for j in run]


def _damaged(edits) -> bytes:
    data = bytearray(BASE)
    for at, value in zip(*edits):
        data[at] = value
    return bytes(data)


@pytest.mark.parametrize("name", MAP.names)
def test_damage_in_each_class_of_bytes_is_refused(name, tmp_path):
    """No damaged file reads (GFGError, nothing else), and `verify` says so in one line with exit
    status 1 (in-process, every eighth case: the command line costs more than the read)."""
    rng = np.random.default_rng(MAP.names.index(name))
    path = tmp_path / "damaged.gfg"
    cases = list(_corruptions(rng, name))
    for k, edits in enumerate(cases):
        data = _damaged(edits)
        with pytest.raises(GFGError):
            read_gfg(data)
        if k % 8 == 0:
            path.write_bytes(data)
            out, err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                status = cli_main(["verify", str(path)])
            lines = out.getvalue().splitlines()
            assert status == 1 and err.getvalue() == "", (status, err.getvalue())
            assert len(lines) == 1 and lines[0].startswith(f"{path}: ") and "OK" not in lines[0], lines
    assert len(cases) >= 2 * min(SAMPLES, len(MAP.offsets(name)))


@pytest.mark.parametrize("name", ZERO_CLASSES)
def test_non_zero_padding_and_reserved_bytes_are_refused_with_the_checksums_made_to_match(name):
    """Every byte of these classes on its own, with every CRC recomputed so that only the zero rule
    is left to catch the damage; for padding the message names the byte's file offset."""
    rng = np.random.default_rng(100 + ZERO_CLASSES.index(name))
    for at in map(int, MAP.offsets(name)):
        data = bytearray(BASE)
        data[at] ^= int(rng.integers(1, 256))
        with pytest.raises(GFGError) as refused:
            read_gfg(bytes(reseal(data)))
        message = str(refused.value)
        if name == "reserved":
            assert "reserved" in message or message.startswith(("header: flags", "header: alignment")), message
        else:
            assert f"file offset {at}" in message, message


def test_the_command_line_reports_damaged_padding_in_one_line_without_a_traceback(tmp_path):
    at = int(MAP.offsets("padding")[-1])
    data = bytearray(BASE)
    data[at] = 0x5A
    path = tmp_path / "padding.gfg"
    path.write_bytes(bytes(data))
    run = subprocess.run([sys.executable, "-m", "voxgi_addon.files.gfg", "verify", str(path)], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and run.stderr == "", run.stderr
    assert run.stdout.splitlines() == [f"{path}: padding after section 13 PRBG: padding: byte at file "
                                       f"offset {at} is 0x5A, not 0 (padding and reserved bytes must be zero)"]


@pytest.mark.parametrize("name", ["PRBG index", "PRBG flags"])
def test_damaged_probe_indices_and_flags_are_refused_with_the_checksums_made_to_match(name):
    """Bowald's index arrays restate the volume list, so any byte of either changed (every CRC
    recomputed) is refused; so is any undefined bit of a probe's flags."""
    rng = np.random.default_rng(200)
    offsets = MAP.offsets(name)
    for at in map(int, offsets):
        data = bytearray(BASE)
        if name == "PRBG flags":  # bits 0-1 of each word are defined: damage the others
            data[at] ^= int(rng.integers(1, 256)) & (0xFC if (at - int(offsets[0])) % 4 == 0 else 0xFF) or 0x80
        else:
            data[at] ^= int(rng.integers(1, 256))
        with pytest.raises(GFGError, match=r"section 13 PRBG: array (VOLUME|SH_INDEX|MASK_INDEX|PROBE_FLAGS)"):
            read_gfg(bytes(reseal(data)))
    assert len(offsets) >= 4 * 15  # 15 probes; the index arrays are longer

"""Fuzzing the GFG reader: truncated, bit-flipped, overwritten and size-inflated files only ever
raise GFGError, never hang, and never allocate more than a small multiple of the file's size.

Plain corruption is caught by the checksums, so most strategies also *reseal* the file (recompute
every CRC) to drive the damage past them into the structural checks. 3,900 cases in total; the
allocation bound is measured with tracemalloc on 300 of them (tracing slows reads ~10x).
"""
import struct
import tracemalloc
import zlib

import numpy as np
import pytest
from gfg_scenes import full_scene
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from voxgi.voxgi_addon.files.gfg import GFGError, GFGScene, Material, read_gfg, to_bytes
from voxgi.voxgi_addon.files.gfg.spec import ARRAY_DESC, KNOWN_KINDS, MATERIAL_RECORD, SECTION_ENTRY, SECTION_PRELUDE

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


@pytest.fixture(scope="module")
def traced():
    tracemalloc.start()
    yield
    tracemalloc.stop()


@settings(FUZZ, max_examples=300)
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


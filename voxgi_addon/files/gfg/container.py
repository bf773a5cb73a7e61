"""The container layer: file header, section table and the generic section body.

A section body is ``prelude | info struct | array table | aligned arrays``. Writers build it
with ``SectionBuilder``; readers get a validated ``SectionView`` whose arrays map straight
into the file's buffer. Every count, offset and size is checked against the section (and the
section against the file) with Python integers before any array exists, so a corrupt file can
neither index out of bounds nor make the reader allocate more than the file's own size.

From format 1.1 the reader also checks that every padding and reserved byte is zero, so that
together with the CRCs no byte of a file goes unverified (docs/gfg.md, "Every byte is checked").
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from . import data_types as dtypes
from .errors import GFGError
from .spec import (
    ALIGNMENT,
    ARRAY_DESC,
    ENDIAN_TAG,
    FILE_HEADER,
    HEADER_CRC_SPAN,
    MAGIC,
    SECTION_ENTRY,
    SECTION_PRELUDE,
    VERSION_MAJOR,
    VERSION_MINOR,
    ZERO_PADDING_SINCE,
)


def align(n: int, to: int = ALIGNMENT) -> int:
    return (n + to - 1) // to * to


def kind_name(kind: bytes) -> str:
    return kind.decode("latin-1").strip() or "?"


# ------------------------------------------------------------------ writing

class SectionBuilder:
    """Collects one section: its info struct and its arrays (in the order added)."""

    def __init__(self, kind: bytes, info: np.ndarray, flags: int = 0, version: int = 1):
        self.kind, self.flags, self.version = kind, flags, version
        self.info = np.asarray(info).reshape(1)
        self._arrays: list[tuple[int, int, int, int, np.ndarray]] = []

    def add(self, role: int, data_type: int, array: np.ndarray, count: int | None = None,
            element_size: int | None = None) -> None:
        """Add ``array`` (any shape; written C-contiguous) as ``count`` elements of ``data_type``."""
        a = np.ascontiguousarray(array)
        if a.dtype.byteorder == ">" or (a.dtype.byteorder == "=" and np.little_endian is False):
            a = a.astype(a.dtype.newbyteorder("<"))
        dt = dtypes.data_type(data_type)
        if element_size is None:
            element_size = dt.size
        if count is None:
            count = a.nbytes // element_size if element_size else 0
        if count * element_size != a.nbytes:
            raise GFGError(f"section {kind_name(self.kind)}", f"array role {role}",
                           f"{a.nbytes} bytes are not {count} elements of {element_size} bytes")
        self._arrays.append((role, data_type, count, element_size, a))

    def build(self) -> tuple[list, int]:
        """(chunks, size) of the section body; chunks are bytes or memoryviews."""
        info = self.info.tobytes()
        table_offset = align(SECTION_PRELUDE.itemsize + len(info), 8)
        data_start = align(table_offset + ARRAY_DESC.itemsize * len(self._arrays))
        table = np.zeros(len(self._arrays), ARRAY_DESC)
        offset = data_start
        for i, (role, data_type, count, element_size, a) in enumerate(self._arrays):
            table[i] = (role, data_type, offset, count, element_size, 0)
            offset = align(offset + a.nbytes)
        prelude = np.array([(len(info), len(self._arrays), table_offset)], SECTION_PRELUDE)
        head = bytearray(data_start)
        head[:16] = prelude.tobytes()
        head[16:16 + len(info)] = info
        head[table_offset:table_offset + table.nbytes] = table.tobytes()
        chunks = [bytes(head)]
        position = data_start
        for (*_, a), entry in zip(self._arrays, table):
            start = int(entry["offset"])
            if start > position:
                chunks.append(bytes(start - position))
            if a.nbytes:
                chunks.append(memoryview(a.reshape(-1)).cast("B"))
            position = start + a.nbytes
        return chunks, position


STREAM_SLICE = 1 << 22  # checksum and write in 4 MiB slices, so each is still in cache


def _crc_and_write(stream, chunks, crc: int = 0) -> int:
    """Write ``chunks`` (stream may be None: checksum only); return the running CRC-32."""
    for chunk in chunks:
        view = memoryview(chunk)
        for start in range(0, len(view), STREAM_SLICE):
            piece = view[start:start + STREAM_SLICE]
            crc = zlib.crc32(piece, crc)
            if stream is not None:
                stream.write(piece)
    return crc


def _header_bytes(table: np.ndarray, file_size: int) -> bytes:
    header = np.zeros(1, FILE_HEADER)
    header[0] = (MAGIC, ENDIAN_TAG, VERSION_MAJOR, VERSION_MINOR, FILE_HEADER.itemsize, file_size,
                 FILE_HEADER.itemsize, len(table), zlib.crc32(table.tobytes()), 0, ALIGNMENT,
                 (0, 0, 0), 0)
    raw = bytearray(header.tobytes())
    raw[HEADER_CRC_SPAN:] = np.array([zlib.crc32(raw[:HEADER_CRC_SPAN])], "<u4").tobytes()
    return bytes(raw) + table.tobytes()


def write_container(stream, sections: list) -> int:
    """Write header, section table and sections to a binary ``stream``; return the byte count.

    A seekable stream is written in one pass (sections checksummed as they are written, then
    the header and table filled in); any other stream gets the checksums computed first.
    """
    built = [s.build() for s in sections]
    table = np.zeros(len(sections), SECTION_ENTRY)
    offset = align(FILE_HEADER.itemsize + SECTION_ENTRY.itemsize * len(sections))
    for i, (section, (_, size)) in enumerate(zip(sections, built)):
        table[i] = (section.kind, section.version, section.flags, offset, size, 0, 0)
        offset = align(offset + size)
    file_size = int(table[-1]["offset"] + table[-1]["size"]) if len(sections) else offset
    one_pass = stream.seekable()
    if not one_pass:
        table["crc"] = [_crc_and_write(None, chunks) for chunks, _ in built]
    head = _header_bytes(table, file_size)
    base = stream.tell() if one_pass else 0
    stream.write(head)
    position = len(head)
    for entry, (chunks, size) in zip(table, built):
        start = int(entry["offset"])
        stream.write(bytes(start - position))
        crc = _crc_and_write(stream, chunks)
        if one_pass:
            entry["crc"] = crc
        position = start + size
    if one_pass:
        stream.seek(base)
        stream.write(_header_bytes(table, file_size))
        stream.seek(base + file_size)
    return file_size


# ------------------------------------------------------------------ reading

@dataclass(frozen=True)
class SectionEntry:
    index: int
    kind: bytes
    version: int
    flags: int
    offset: int
    size: int
    crc: int
    reserved: int = 0


@dataclass(frozen=True)
class Header:
    version: tuple[int, int]
    file_size: int
    sections: tuple[SectionEntry, ...]

    @property
    def zero_padding(self) -> bool:
        """Whether padding and reserved bytes must be zero (format 1.1 on; 1.0 did not say)."""
        return self.version >= ZERO_PADDING_SINCE


def check_zero(buf: memoryview, start: int, end: int, where: str, field: str = "padding",
               base: int = 0) -> None:
    """Raise unless ``buf[start:end]`` is all zero; the message names the first non-zero byte's
    file offset (``base`` + its offset in ``buf``)."""
    if end <= start:
        return
    a = np.frombuffer(buf, np.uint8, end - start, start)
    if a.any():
        at = int(np.argmax(a != 0))
        raise GFGError(where, field, f"byte at file offset {base + start + at} is 0x{int(a[at]):02X}, "
                       "not 0 (padding and reserved bytes must be zero)")


def _check_reserved(value, where: str, field: str) -> None:
    if int(value):
        raise GFGError(where, field, f"0x{int(value):X} is not 0 (reserved fields must be zero)")


def _check_zero_bytes(buf: memoryview, h, table_end: int, entries: list[SectionEntry]) -> None:
    """Format 1.1 rules for the bytes outside sections: reserved header and table fields are zero,
    and so is every byte between the header, the table, the sections and the end of the file."""
    _check_reserved(h["flags"], "header", "flags")
    if int(h["alignment"]) != ALIGNMENT:
        raise GFGError("header", "alignment", f"{int(h['alignment'])} is not {ALIGNMENT}")
    for k, word in enumerate(h["reserved"]):
        _check_reserved(word, "header", f"reserved[{k}]")
    for e in entries:
        _check_reserved(e.reserved, f"section table entry {e.index}", "reserved")
    check_zero(buf, FILE_HEADER.itemsize, int(h["table_offset"]), "header", "padding before the table")
    previous, after = table_end, "the section table"
    for e in entries:
        check_zero(buf, previous, e.offset, f"padding after {after}")
        previous, after = e.offset + e.size, f"section {e.index} {kind_name(e.kind)}"
    check_zero(buf, previous, len(buf), f"padding after {after}")


def parse_header(buf: memoryview) -> Header:
    """Validate the header and section table of a file held in ``buf`` (any length)."""
    n = len(buf)
    if n < FILE_HEADER.itemsize:
        raise GFGError("header", "file size", f"{n} bytes is shorter than the 64-byte header")
    h = np.frombuffer(buf, FILE_HEADER, 1, 0)[0]
    if bytes(h["magic"]) != MAGIC:
        raise GFGError("header", "magic", f"{bytes(buf[:4])!r} is not {MAGIC!r}: not a GFG file")
    if int(h["endian_tag"]) != ENDIAN_TAG:
        raise GFGError("header", "endian_tag", f"0x{int(h['endian_tag']):08X} is not 0x{ENDIAN_TAG:08X}: "
                       "the file is not little-endian")
    crc = zlib.crc32(buf[:HEADER_CRC_SPAN])
    if crc != int(h["header_crc"]):
        raise GFGError("header", "header_crc", f"checksum 0x{crc:08X} does not match the stored "
                       f"0x{int(h['header_crc']):08X}")
    major, minor = int(h["version_major"]), int(h["version_minor"])
    if major != VERSION_MAJOR:
        raise GFGError("header", "version_major", f"version {major}.{minor} is not readable by a "
                       f"{VERSION_MAJOR}.{VERSION_MINOR} reader")
    if int(h["header_size"]) < FILE_HEADER.itemsize:
        raise GFGError("header", "header_size", f"{int(h['header_size'])} is less than 64")
    file_size = int(h["file_size"])
    if file_size != n:
        raise GFGError("header", "file_size", f"the header says {file_size} bytes but the file has {n}"
                       + (" (truncated)" if file_size > n else ""))
    count, table_offset = int(h["section_count"]), int(h["table_offset"])
    table_end = table_offset + count * SECTION_ENTRY.itemsize
    if table_offset < int(h["header_size"]) or table_offset % 8 or table_end > n:
        raise GFGError("header", "table_offset/section_count",
                       f"a table of {count} sections at {table_offset} does not fit in {n} bytes")
    crc = zlib.crc32(buf[table_offset:table_end])
    if crc != int(h["table_crc"]):
        raise GFGError("section table", "table_crc", f"checksum 0x{crc:08X} does not match the "
                       f"stored 0x{int(h['table_crc']):08X}")
    table = np.frombuffer(buf, SECTION_ENTRY, count, table_offset)
    entries, previous_end = [], table_end
    for i, e in enumerate(table):
        where = f"section table entry {i}"
        offset, size = int(e["offset"]), int(e["size"])
        if offset % ALIGNMENT:
            raise GFGError(where, "offset", f"{offset} is not a multiple of {ALIGNMENT}")
        if offset < previous_end:
            raise GFGError(where, "offset", f"{offset} overlaps the table or the previous section "
                           f"(which ends at {previous_end})")
        if offset + size > n:
            raise GFGError(where, "size", f"{size} bytes at {offset} run past the end of the "
                           f"{n}-byte file")
        entries.append(SectionEntry(i, bytes(e["kind"]), int(e["version"]), int(e["flags"]),
                                    offset, size, int(e["crc"]), int(e["reserved"])))
        previous_end = offset + size
    header = Header((major, minor), file_size, tuple(entries))
    if header.zero_padding:
        _check_zero_bytes(buf, h, table_end, entries)
    return header


def check_crc(buf: memoryview, entry: SectionEntry, where: str) -> None:
    crc = zlib.crc32(buf[entry.offset:entry.offset + entry.size])
    if crc != entry.crc:
        raise GFGError(where, "crc", f"checksum 0x{crc:08X} does not match the stored 0x{entry.crc:08X}")


@dataclass(frozen=True)
class ArrayDesc:
    position: int  # in the array table
    role: int
    data_type: int
    offset: int
    count: int
    element_size: int

    @property
    def nbytes(self) -> int:
        return self.count * self.element_size


class SectionView:
    """A section whose prelude and array table have been validated against its size.

    ``zero_padding`` (format 1.1 on): the bytes between the info struct, the array table and
    the arrays, and every reserved field of the array table, info struct and records, must be 0.
    """

    def __init__(self, buf: memoryview, entry: SectionEntry, zero_padding: bool = False):
        self.entry = entry
        self.zero_padding = zero_padding
        self.where = f"section {entry.index} {kind_name(entry.kind)}"
        self.buf = buf[entry.offset:entry.offset + entry.size]
        size = entry.size
        if size < SECTION_PRELUDE.itemsize:
            self.fail("size", f"{size} bytes is shorter than the 16-byte prelude")
        p = np.frombuffer(self.buf, SECTION_PRELUDE, 1, 0)[0]
        self.info_size = int(p["info_size"])
        array_count, table_offset = int(p["array_count"]), int(p["array_table_offset"])
        if SECTION_PRELUDE.itemsize + self.info_size > size:
            self.fail("info_size", f"{self.info_size} bytes of info do not fit in {size} bytes")
        table_end = table_offset + array_count * ARRAY_DESC.itemsize
        if table_offset % 8 or table_offset < SECTION_PRELUDE.itemsize + self.info_size or table_end > size:
            self.fail("array_table_offset/array_count",
                      f"a table of {array_count} arrays at {table_offset} does not fit in {size} bytes")
        arrays = []
        for i, d in enumerate(np.frombuffer(self.buf, ARRAY_DESC, array_count, table_offset)):
            a = ArrayDesc(i, int(d["role"]), int(d["data_type"]), int(d["offset"]), int(d["count"]),
                          int(d["element_size"]))
            field = f"array {i} (role {a.role})"
            if a.offset % 8 or a.offset < table_end:
                self.fail(field + " offset", f"{a.offset} is unaligned or inside the section's tables")
            if a.offset + a.nbytes > size:
                self.fail(field + " count", f"{a.count} elements of {a.element_size} bytes at "
                          f"{a.offset} run past the section's {size} bytes")
            if zero_padding:
                _check_reserved(d["reserved"], self.where, field + " reserved")
            arrays.append(a)
        ordered = sorted(arrays, key=lambda a: a.offset)
        for a, b in zip(ordered, ordered[1:]):
            if a.offset + a.nbytes > b.offset:
                self.fail(f"array {b.position} (role {b.role}) offset", f"overlaps array {a.position}")
        self.arrays = arrays
        if zero_padding:  # the gaps: info → array table → arrays → the section's end
            gaps = [(SECTION_PRELUDE.itemsize + self.info_size, table_offset)]
            end = table_end
            for a in ordered:
                gaps.append((end, a.offset))
                end = a.offset + a.nbytes
            gaps.append((end, size))
            for start, stop in gaps:
                check_zero(self.buf, start, stop, self.where, base=entry.offset)

    def fail(self, field: str, problem: str):
        raise GFGError(self.where, field, problem)

    def name_as(self, label: str) -> None:
        """Add the item's name to error messages ("section 4 MESH 'Cube'")."""
        self.where = f"section {self.entry.index} {kind_name(self.entry.kind)} '{label}'"

    def info(self, dtype: np.dtype):
        """The info struct as a numpy record (newer, longer info structs are accepted)."""
        if self.info_size < dtype.itemsize:
            self.fail("info_size", f"{self.info_size} is shorter than the {dtype.itemsize} bytes of "
                      "this kind's info")
        info = np.frombuffer(self.buf, dtype, 1, SECTION_PRELUDE.itemsize)[0]
        if self.zero_padding and "reserved" in dtype.names:
            _check_reserved(info["reserved"], self.where, "info.reserved")
        return info

    def descs(self, role: int) -> list[ArrayDesc]:
        return [a for a in self.arrays if a.role == role]

    def desc(self, role: int, name: str, required: bool = True) -> ArrayDesc | None:
        found = self.descs(role)
        if len(found) > 1:
            self.fail(f"array {name}", f"appears {len(found)} times")
        if not found:
            if required:
                self.fail(f"array {name}", "is missing")
            return None
        return found[0]

    def array(self, role: int, name: str, data_types, count: int | None, *, record=None,
              required: bool = True) -> np.ndarray | None:
        """Map the array of ``role`` (zero-copy) after checking its type, element size and count.

        data_types : allowed codes; record : the struct dtype when the code is RECORD.
        count : the element count the rest of the file implies (None: any).
        Returns (count,) records or scalars, or (count, components) for multi-component types.
        """
        d = self.desc(role, name, required)
        if d is None:
            return None
        return self.map(d, name, data_types, count, record=record)

    def map(self, d: ArrayDesc, name: str, data_types, count, *, record=None):
        field = f"array {name}"
        if d.data_type not in data_types:
            allowed = ", ".join(dtypes.name_of(c) for c in data_types)
            self.fail(field + " data_type", f"{dtypes.name_of(d.data_type)} is not one of {allowed}")
        if count is not None and d.count != count:
            self.fail(field + " count", f"{d.count} elements, expected {count}")
        if d.data_type == dtypes.RECORD:
            if d.element_size != record.itemsize:
                self.fail(field + " element_size", f"{d.element_size} is not the record's {record.itemsize}")
            records = np.frombuffer(self.buf, record, d.count, d.offset)
            if self.zero_padding and "reserved" in record.names and records["reserved"].any():
                k = int(np.argmax(records["reserved"] != 0))
                _check_reserved(records["reserved"][k], self.where, f"{field} record {k} reserved")
            return records
        dt = dtypes.data_type(d.data_type)
        if d.element_size != dt.size:
            self.fail(field + " element_size", f"{d.element_size} is not the {dt.size} bytes of {dt.name}")
        flat = np.frombuffer(self.buf, dt.base, d.count * dt.components, d.offset)
        return flat.reshape(d.count, dt.components) if dt.components > 1 else flat

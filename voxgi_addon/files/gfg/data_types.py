"""GFG data type codes (the original's numbering) with their storage and float codecs.

A data type is how one element of an array or one vertex component is stored: a numpy base
dtype and a component count (``FLOAT_3`` = three ``<f4``), or a packed 32-bit word
(``NORM_2_10_10_10``, ``UINT_10F_11F_11F``, ``CUSTOM_1_15N_16N``, ``UINT_2_10_10_10``).
``encode`` turns float values into storage, ``decode`` turns storage back into floats;
``encode(decode(q))`` gives ``q`` back for every supported type, so a decoded-and-re-encoded
file is byte-identical.

Two codes do not store data: ``RECORD`` (a struct fixed by the array's role) and ``BYTES``
(an opaque vertex block whose element size is its stride).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DataType:
    code: int
    name: str
    base: np.dtype | None  # numpy scalar dtype of one component (None: RECORD/BYTES)
    components: int
    kind: str  # 'float', 'int', 'norm', 'unorm', 'packed', 'record', 'bytes'

    @property
    def size(self) -> int:
        return 0 if self.base is None else self.base.itemsize * self.components


_TABLE: dict[int, DataType] = {}


def _add(code, name, base, components, kind):
    _TABLE[code] = DataType(code, name, None if base is None else np.dtype(base), components, kind)


for _i in range(4):
    _n = _i + 1
    _add(0 + _i, f"HALF_{_n}", "<f2", _n, "float")
    _add(4 + _i, f"FLOAT_{_n}", "<f4", _n, "float")
    _add(8 + _i, f"DOUBLE_{_n}", "<f8", _n, "float")
    # 12-15 QUADRUPLE_*: no portable numpy storage; unsupported.
    for _block, (_label, _base) in enumerate([
            ("INT8", "<i1"), ("UINT8", "<u1"), ("INT16", "<i2"), ("UINT16", "<u2"),
            ("INT32", "<i4"), ("UINT32", "<u4"), ("INT64", "<i8"), ("UINT64", "<u8")]):
        _add(16 + 4 * _block + _i, f"{_label}_{_n}", _base, _n, "int")
    for _block, (_label, _base, _kind) in enumerate([
            ("NORM8", "<i1", "norm"), ("UNORM8", "<u1", "unorm"), ("NORM16", "<i2", "norm"),
            ("UNORM16", "<u2", "unorm"), ("NORM32", "<i4", "norm"), ("UNORM32", "<u4", "unorm")]):
        _add(48 + 4 * _block + _i, f"{_label}_{_n}", _base, _n, _kind)
_add(72, "NORM_2_10_10_10", "<u4", 1, "packed")
_add(73, "UNORM_2_10_10_10", "<u4", 1, "packed")
_add(74, "UINT_10F_11F_11F", "<u4", 1, "packed")
_add(75, "CUSTOM_1_15N_16N", "<u4", 1, "packed")
# 76-80 (CUSTOM_TANG_H_2N, UNORM8_4_4, UNORM16_2_4, UINT8_4_4, UINT16_2_4): unsupported.
_add(81, "UINT_2_10_10_10", "<u4", 1, "packed")
_add(82, "QUATERNION", "<f4", 4, "float")
RECORD, BYTES = 1000, 1001
_add(RECORD, "RECORD", None, 0, "record")
_add(BYTES, "BYTES", None, 0, "bytes")

CODES = {dt.name: code for code, dt in _TABLE.items()}


def data_type(code: int) -> DataType | None:
    """The DataType of ``code``, or None for an unknown or unsupported code."""
    return _TABLE.get(int(code))


def code_of(name: str) -> int:
    """The code of a data type name such as ``'FLOAT_3'``."""
    return CODES[name]


def name_of(code: int) -> str:
    dt = _TABLE.get(int(code))
    return dt.name if dt is not None else f"UNKNOWN({int(code)})"


# ------------------------------------------------------------------ codecs

def _max(base: np.dtype) -> int:
    return int(np.iinfo(base).max)


def _snorm_bits(v, bits):
    q = np.clip(np.rint(np.asarray(v, np.float64) * ((1 << (bits - 1)) - 1)),
                -((1 << (bits - 1)) - 1), (1 << (bits - 1)) - 1).astype(np.int64)
    return q & ((1 << bits) - 1)


def _snorm_value(field, bits):
    field = field.astype(np.int64)
    signed = np.where(field >= 1 << (bits - 1), field - (1 << bits), field)
    return np.maximum(signed / ((1 << (bits - 1)) - 1), -1.0)


def _pack_fields(fields, widths) -> np.ndarray:
    word = np.zeros(len(fields[0]), np.uint64)
    shift = 0
    for f, w in zip(fields, widths):
        word |= (np.asarray(f, np.int64).astype(np.uint64) & np.uint64((1 << w) - 1)) << np.uint64(shift)
        shift += w
    return word.astype("<u4")


def _unpack_fields(words, widths):
    w = np.asarray(words).reshape(-1).astype(np.uint64)
    out, shift = [], 0
    for width in widths:
        out.append((w >> np.uint64(shift)) & np.uint64((1 << width) - 1))
        shift += width
    return out


def _small_float_encode(v, mantissa_bits):
    """Non-negative floats → unsigned 5-bit-exponent floats (as in R11G11B10F), nearest even."""
    h = np.clip(np.nan_to_num(np.asarray(v, np.float32), nan=0.0, posinf=65000.0), 0.0, 65000.0)
    bits = h.astype("<f2").view("<u2").astype(np.uint32)
    drop = 10 - mantissa_bits
    half_step = (1 << (drop - 1)) - 1 + ((bits >> drop) & 1)  # round to nearest, ties to even
    q = (bits + half_step) >> drop
    return np.minimum(q, (0x1E << mantissa_bits) | ((1 << mantissa_bits) - 1))  # largest finite


def _small_float_decode(q, mantissa_bits):
    bits = (q.astype(np.uint32) << (10 - mantissa_bits)).astype("<u2")
    return bits.view("<f2").astype(np.float32)


def encode(values, code: int) -> np.ndarray:
    """Float (or integer) values ``(N, k)`` → storage ``(N, components)`` of data type ``code``.

    Normalized types round to nearest and clamp; ``NORM_2_10_10_10`` takes xyz (w = 0) or xyzw;
    ``CUSTOM_1_15N_16N`` takes unit xyz (z rebuilt from x, y and its sign bit);
    ``UINT_10F_11F_11F`` takes non-negative RGB; ``UINT_2_10_10_10`` takes integer xyz in
    [0, 1024) and an optional 2-bit w.
    """
    dt = _TABLE[code]
    v = np.asarray(values)
    if v.ndim == 1:
        v = v[:, None]
    if dt.kind == "float":
        return np.ascontiguousarray(v, dtype=dt.base)
    if dt.kind == "int":
        info = np.iinfo(dt.base)
        return np.clip(np.rint(v.astype(np.float64)), info.min, info.max).astype(dt.base)
    if dt.kind == "norm":
        m = _max(dt.base)
        return np.clip(np.rint(np.nan_to_num(v.astype(np.float64)) * m), -m, m).astype(dt.base)
    if dt.kind == "unorm":
        m = _max(dt.base)
        return np.clip(np.rint(np.nan_to_num(v.astype(np.float64)) * m), 0, m).astype(dt.base)
    return _encode_packed(v, dt.name)[:, None]


def _encode_packed(v, name):
    v64 = np.nan_to_num(v.astype(np.float64))
    if name == "NORM_2_10_10_10":
        w = v64[:, 3] if v64.shape[1] > 3 else np.zeros(len(v64))
        return _pack_fields([_snorm_bits(v64[:, i], 10) for i in range(3)] + [_snorm_bits(w, 2)],
                            (10, 10, 10, 2))
    if name == "UNORM_2_10_10_10":
        w = v64[:, 3] if v64.shape[1] > 3 else np.zeros(len(v64))
        q = [np.clip(np.rint(v64[:, i] * 1023), 0, 1023) for i in range(3)]
        return _pack_fields(q + [np.clip(np.rint(w * 3), 0, 3)], (10, 10, 10, 2))
    if name == "UINT_10F_11F_11F":
        return _pack_fields([_small_float_encode(v[:, 0], 6), _small_float_encode(v[:, 1], 6),
                             _small_float_encode(v[:, 2], 5)], (11, 11, 10))
    if name == "CUSTOM_1_15N_16N":
        x = np.clip(np.rint(v64[:, 0] * 32767), -32767, 32767)
        y = np.clip(np.rint(v64[:, 1] * 16383), -16383, 16383)
        return _pack_fields([x, y, np.signbit(v[:, 2]).astype(np.int64)], (16, 15, 1))
    if name == "UINT_2_10_10_10":
        w = v[:, 3] if v.shape[1] > 3 else np.zeros(len(v), np.int64)
        return _pack_fields([v[:, 0], v[:, 1], v[:, 2], w], (10, 10, 10, 2))
    raise ValueError(f"no codec for {name}")


def decode(storage, code: int) -> np.ndarray:
    """Storage of data type ``code`` → ``(N, k)`` values (float32; float64 for doubles and
    32-bit norms; integers for integer types; int64 xyzw for ``UINT_2_10_10_10``)."""
    dt = _TABLE[code]
    s = np.asarray(storage)
    if s.ndim == 1:
        s = s[:, None]
    if dt.kind == "float":
        return s.astype(np.float64 if dt.base.itemsize == 8 else np.float32)
    if dt.kind == "int":
        return s
    if dt.kind in ("norm", "unorm"):
        ftype = np.float64 if dt.base.itemsize >= 4 else np.float32
        x = s.astype(ftype) / ftype(_max(dt.base))
        return np.maximum(x, ftype(-1.0)) if dt.kind == "norm" else x
    name = dt.name
    if name == "NORM_2_10_10_10":
        f = _unpack_fields(s, (10, 10, 10, 2))
        return np.stack([_snorm_value(f[i], 10) for i in range(3)] + [_snorm_value(f[3], 2)],
                        axis=1).astype(np.float32)
    if name == "UNORM_2_10_10_10":
        f = _unpack_fields(s, (10, 10, 10, 2))
        return np.stack([f[0] / 1023, f[1] / 1023, f[2] / 1023, f[3] / 3], axis=1).astype(np.float32)
    if name == "UINT_10F_11F_11F":
        f = _unpack_fields(s, (11, 11, 10))
        return np.stack([_small_float_decode(f[0], 6), _small_float_decode(f[1], 6),
                         _small_float_decode(f[2], 5)], axis=1)
    if name == "CUSTOM_1_15N_16N":
        f = _unpack_fields(s, (16, 15, 1))
        x, y = _snorm_value(f[0], 16), _snorm_value(f[1], 15)
        z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
        return np.stack([x, y, np.where(f[2] == 1, -z, z)], axis=1).astype(np.float32)
    if name == "UINT_2_10_10_10":
        return np.stack(_unpack_fields(s, (10, 10, 10, 2)), axis=1).astype(np.int64)
    raise ValueError(f"no codec for {name}")

"""A minimal PNG writer (8-bit RGB, stdlib zlib) for preview strips and reports."""
from __future__ import annotations

import struct
import zlib

import numpy as np


def to_srgb8(linear: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """(H, W, 3) linear float → (H, W, 3) uint8 sRGB (clamped)."""
    x = np.clip(np.nan_to_num(np.asarray(linear, np.float64) * exposure), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.rint(srgb * 255).astype(np.uint8)


def write_png(path, rgb8: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image."""
    img = np.ascontiguousarray(rgb8, dtype=np.uint8)
    h, w, _ = img.shape
    raw = b"".join(b"\x00" + img[row].tobytes() for row in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6))
                + chunk(b"IEND", b""))


def image_strip(images, gap: int = 2, scale: int = 1) -> np.ndarray:
    """Concatenate (H, W, 3) uint8 images left to right with a black gap; nearest upscale."""
    parts = []
    for i, im in enumerate(images):
        if i:
            parts.append(np.zeros((im.shape[0], gap, 3), np.uint8))
        parts.append(im)
    strip = np.concatenate(parts, axis=1)
    return strip.repeat(scale, axis=0).repeat(scale, axis=1)

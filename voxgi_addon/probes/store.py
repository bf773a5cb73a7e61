"""Probe grids as compact bytes, for keeping them with a .blend (docs/probes.md "Persistence").

The bytes are a GFG file (docs/gfg.md) holding only PRBG sections — so every byte is checked on
the way back — compressed with zlib; ``to_text``/``from_text`` wrap them in base64 for a Blender
Text datablock.
"""
from __future__ import annotations

import base64
import zlib

import numpy as np

from ..files.gfg import GFGError, GFGScene, read_gfg, to_bytes
from .grid import ProbeGrid

__all__ = ["grids_to_bytes", "grids_from_bytes", "to_text", "from_text", "TEXT_HEADER"]

TEXT_HEADER = "VoxGI probe grids (zlib + base64 GFG); do not edit\n"


def grids_to_bytes(grids: list[ProbeGrid]) -> bytes:
    return zlib.compress(to_bytes(GFGScene(probe_grids=list(grids))), 6)


def grids_from_bytes(data: bytes) -> list[ProbeGrid]:
    """The grids back, with their arrays copied out of the buffer. Raises ``GFGError``."""
    try:
        raw = zlib.decompress(data)
    except zlib.error as error:
        raise GFGError("probe store", "zlib", str(error)) from None
    scene = read_gfg(raw)
    out = []
    for g in scene.probe_grids:
        fields = {k: (np.array(v) if isinstance(v, np.ndarray) else v) for k, v in vars(g).items()}
        out.append(ProbeGrid(**fields))
    return out


def to_text(grids: list[ProbeGrid]) -> str:
    body = base64.b64encode(grids_to_bytes(grids)).decode("ascii")
    return TEXT_HEADER + "\n".join(body[i:i + 76] for i in range(0, len(body), 76)) + "\n"


def from_text(text: str) -> list[ProbeGrid]:
    if not text.startswith(TEXT_HEADER):
        raise GFGError("probe store", "header", "the text is not a VoxGI probe store")
    try:
        data = base64.b64decode("".join(text[len(TEXT_HEADER):].split()), validate=True)
    except ValueError as error:
        raise GFGError("probe store", "base64", str(error)) from None
    return grids_from_bytes(data)

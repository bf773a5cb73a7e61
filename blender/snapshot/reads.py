"""How often the snapshot read the expensive things (main thread): evaluated meshes
(``Object.to_mesh``), materials and worlds. A pose or a move needs none of them
(docs/gi_pipeline.md "Posed updates"); tests count them to hold the pose path to that.
"""
from __future__ import annotations

__all__ = ["KINDS", "count", "read_counts"]

KINDS = ("meshes", "materials", "worlds")
_COUNTS = dict.fromkeys(KINDS, 0)


def count(kind: str, n: int = 1) -> None:
    """Note ``n`` reads of ``kind`` (one of ``KINDS``)."""
    _COUNTS[kind] += n


def read_counts() -> dict[str, int]:
    """Reads so far this session, by kind (a copy: subtract two of them for a span)."""
    return dict(_COUNTS)

"""Turn a snapshot and a ``build_scene_caches`` result into report lines (no bpy).

A report line is ``(level, message)`` with level 'ERROR', 'WARNING' or 'INFO', as
``Operator.report`` takes them.
"""
from __future__ import annotations

MEGABYTE = 1_000_000


def cascade_lines(result) -> list[tuple[str, str]]:
    """One INFO line per cascade: span, voxel count and memory, then the total."""
    lines = [
        ("INFO", f"Cascade {s.cascade}: span {s.span:g} m, {s.voxel_count:,} voxels, "
                 f"{s.nbytes / MEGABYTE:.2f} MB")
        for s in result.cascade_stats
    ]
    lines.append(("INFO", f"Total: {result.total_voxels:,} voxels, {result.total_bytes / MEGABYTE:.2f} MB"))
    return lines


def warning_lines(snapshot_warnings, result) -> list[tuple[str, str]]:
    """WARNING lines, each once: snapshot and engine warnings, dropped triangles, skipped meshes.

    The engine may already carry the snapshot's warnings and describe dropped triangles in
    ``result.warnings``; a dropped-triangle line is only added for a mesh no warning names.
    """
    messages = list(dict.fromkeys([*snapshot_warnings, *result.warnings]))
    for mesh, count in result.dropped_triangles.items():
        if count and not any(f"'{mesh}'" in m and "dropped" in m for m in messages):
            messages.append(f"Mesh '{mesh}': dropped {count} degenerate (zero-area) or non-finite triangles")
    messages += [str(skip) for skip in result.skipped]
    return [("WARNING", m) for m in messages]


def timing_line(timings: dict[str, float]) -> tuple[str, str]:
    """One INFO line with the seconds spent per stage."""
    stages = ", ".join(f"{name} {seconds:.3f} s" for name, seconds in timings.items())
    return ("INFO", f"Timings: {stages}")

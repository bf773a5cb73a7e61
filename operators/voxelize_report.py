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
    """WARNING lines: snapshot problems, engine warnings, dropped triangles, skipped meshes."""
    lines = [("WARNING", w) for w in snapshot_warnings]
    lines += [("WARNING", w) for w in result.warnings]
    lines += [
        ("WARNING", f"Mesh '{mesh}': dropped {count} degenerate (zero-area) or non-finite triangles")
        for mesh, count in result.dropped_triangles.items() if count
    ]
    lines += [("WARNING", str(skip)) for skip in result.skipped]
    return lines


def timing_line(timings: dict[str, float]) -> tuple[str, str]:
    """One INFO line with the seconds spent per stage."""
    stages = ", ".join(f"{name} {seconds:.3f} s" for name, seconds in timings.items())
    return ("INFO", f"Timings: {stages}")

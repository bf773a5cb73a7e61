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


# Prefixes of the INFO lines above, which the panel already shows as tables.
TABLE_LINE_PREFIXES = ("Cascade ", "Total: ", "Timings: ")


def panel_lines(report, limit: int = 6) -> tuple[list[tuple[str, str]], int]:
    """The report lines a panel shows as text (not the ones it draws as tables), at most
    ``limit`` of them, errors first; returns (lines, number left out)."""
    lines = [(lvl, m) for lvl, m in report
             if not (lvl == "INFO" and m.startswith(TABLE_LINE_PREFIXES))]
    order = {"ERROR": 0, "WARNING": 1}
    lines.sort(key=lambda line: order.get(line[0], 2))  # stable: report order within a level
    return lines[:limit], max(0, len(lines) - limit)


# Plain-text tables (the demo's console output; a panel may reuse the rows).
TIMING_STAGES = ("snapshot", "check", "voxelize", "attributes", "pack")


def format_table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> list[str]:
    """Right-aligned text columns under a header and a rule; the first column is left-aligned."""
    widths = [max(len(str(r[i])) for r in (header, *rows)) for i in range(len(header))]

    def line(cells):
        return "  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w)
                         for i, (c, w) in enumerate(zip(cells, widths)))

    return [line(header), "  ".join("-" * w for w in widths), *(line(r) for r in rows)]


def cascade_table(result) -> list[str]:
    """One row per cascade (span in m, voxel count, MB), then the total."""
    rows = [(str(s.cascade), f"{s.span:g}", f"{s.voxel_count:,}", f"{s.nbytes / MEGABYTE:.2f}")
            for s in result.cascade_stats]
    rows.append(("total", "", f"{result.total_voxels:,}", f"{result.total_bytes / MEGABYTE:.2f}"))
    return format_table(("cascade", "span (m)", "voxels", "MB"), rows)


def timing_table(timings: dict[str, float], total: float | None = None) -> list[str]:
    """Milliseconds per stage (``TIMING_STAGES`` first, 0 when absent, then any others).

    total : wall-clock seconds of the whole run; defaults to the sum of the stages.
    """
    names = [*TIMING_STAGES, *(n for n in timings if n not in TIMING_STAGES)]
    rows = [(n, f"{timings.get(n, 0.0) * 1000:.1f}") for n in names]
    rows.append(("total", f"{(sum(timings.values()) if total is None else total) * 1000:.1f}"))
    return format_table(("stage", "ms"), rows)


def timing_text(timings: dict[str, float]) -> str:
    return ", ".join(f"{name} {seconds * 1000:.1f} ms" for name, seconds in timings.items())


def octree_text(octree) -> str:
    """Node count and MB per octree level, e.g. 'L6 dense 13,184 nodes 17.3 MB'."""
    return "; ".join(f"L{s.level} {s.kind} {s.nodes:,} nodes {s.bytes / 2**20:.2f} MB"
                     for s in octree.stats())

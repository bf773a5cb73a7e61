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


def _metres(v) -> str:
    return f"{v:.3g}"


def fit_text(state, fit=None, view_ahead: float = 1.0) -> str:
    """How the cascades of ``state`` were placed: the view fit (Auto) or the camera (Manual)."""
    grid = state.grids[0]
    shape = f"{grid.resolution}³ × {len(state.grids)} cascades, base span {grid.span:g} m"
    if fit is None:
        return f"Voxel fit: Manual, {shape}, centred {view_ahead:g} × half the finest cascade " \
               "ahead of the camera"
    centre = ", ".join(_metres(c) for c in fit.centre)
    return (f"Voxel fit: Auto, {shape}, centred on the view at ({centre}) m; voxel volume "
            f"~{fit.memory_bytes / MEGABYTE:.0f} MB of a {fit.budget_bytes / MEGABYTE:.0f} MB "
            f"budget, caches ~{fit.cache_bytes / MEGABYTE:.0f} MB")


def cascade_cover_rows(state) -> list[tuple[str, str, str, str]]:
    """Per cascade: (name with span and resolution, extent, share of the visible points whose
    finest cascade it is, voxel count); a last row for the points outside every cascade."""
    shares = state.view_shares
    rows = []
    for grid, count in zip(state.grids, state.voxel_counts):
        lo, hi = grid.extent
        extent = f"{_metres(grid.size)} m cube, " + " ".join(
            f"{axis} {_metres(a)}..{_metres(b)}" for axis, a, b in zip("xyz", lo, hi))
        share = "?" if shares is None else f"{shares[grid.index]:.1%} of the view"
        rows.append((f"Cascade {grid.index} ({grid.span:g} m, {grid.resolution}³)", extent, share,
                     f"{count:,} voxels"))
    if shares is not None:
        rows.append(("Outside every cascade", "", f"{shares[-1]:.1%} of the view", ""))
    return rows


def coverage_lines(state, fit=None, view_ahead: float = 1.0) -> list[tuple[str, str]]:
    """INFO lines after an update or a preview: how the cascades were placed, then per cascade
    its span, extent (metres), share of the visible points (the view probe's pixels) and
    voxels (docs/gi_pipeline.md "View-fitted cascades")."""
    lines = [("INFO", fit_text(state, fit, view_ahead))]
    for name, extent, share, count in cascade_cover_rows(state):
        lines.append(("INFO", ": ".join([name, ", ".join(p for p in (extent, share, count) if p)])))
    return lines


# Prefixes of the INFO lines above, which the panel already shows as tables.
TABLE_LINE_PREFIXES = ("Cascade ", "Total: ", "Timings: ", "Outside every cascade")


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

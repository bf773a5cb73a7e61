"""Bench section "gi": runs tools/bench/bench_gi_blender.py with the bpy venv (.venv), since Cycles
and the add-on's snapshot need Blender; ``make bench`` builds .venv first."""
from __future__ import annotations

import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def run_scripts(scripts, quick: bool = False, out=print) -> str:
    """Run each of ``scripts`` (``run(script=…)``); one that fails does not hide the others'
    tables, and the section fails at the end."""
    tables, failed = [], []
    for name in scripts:
        try:
            tables.append(run(quick, out, name))
        except RuntimeError as exc:
            failed.append(str(exc))
            out(f"**{name} failed** (the section goes on): {str(exc)[-600:]}\n")
    if failed:
        raise RuntimeError("; ".join(f.splitlines()[0] for f in failed))
    return "\n".join(tables)


def run(quick: bool = False, out=print, script: str | None = None) -> str:
    """Section "gi": per-update times (bench_gi_blender.py), the issue scenes against
    Cycles 16/64/256 spp and the default preview times (bench_scenes_blender.py), then the
    multi-bounce interiors at the default Bounces and at 1 against Cycles 16/64 spp with and
    without OIDN at its default light paths (bench_bounces_blender.py)."""
    if script is None:
        return run_scripts(("bench_gi_blender.py", "bench_scenes_blender.py",
                            "bench_bounces_blender.py"), quick, out)
    python = ROOT / ".venv" / "bin" / "python"
    if not python.exists():
        raise RuntimeError("the bpy venv .venv is missing: run `make venv` (make bench does)")
    cmd = [str(python), str(ROOT / "tools" / "bench" / script)] + (["--quick"] if quick else [])
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{script} failed:\n{done.stderr[-2000:]}")
    table = "\n".join(line for line in done.stdout.splitlines()
                      if line.startswith(("|", "###", "Note:", "Goal")) or not line.strip())
    out(table.strip() + "\n")
    return table

"""Bench section "preview" (docs/gi_pipeline.md "Where a preview's time goes"): what one
preview costs beside Cycles 16 and 64 spp +
OpenImageDenoise, and where its time goes against this machine's floor.

Each scene and size runs in a fresh process (``bench_preview_blender.py``, the bpy venv) with
an empty on-disk shader cache of its own (``MESA_SHADER_CACHE_DIR``), so "first" is the first
preview on a new machine and "warm" the next ones (the radiance cache built again each time,
as after any edit); a second process then times its first preview on the shader cache the
first one filled: "later session", the first preview of every session after the first (Mesa
keeps compiled kernels on disk, as GPU drivers do). Tables:

1. per scene and size: first and warm preview time, Combined error against Cycles at its
   default light paths, Cycles 16 / 64 spp + OIDN's time and error in the same process, and
   the goal (error ≤ Cycles 16 + OIDN's, warm ≤ ⅓ of its time, first ≤ warm + its
   time); beside them how far a second reference (another seed) lies from the first — the
   references' own noise, under which no error of the row can go — and the errors against
   the two references' mean (half their noise's variance);
2. per scene at each size: the warm preview split into its stages (each dispatch timed to its
   completion), each stage's rays (BVH traversals) and texel fetches, and its floor — that
   work at the rates trivial kernels reach on the same BVH in the same process — and what the
   stage cost more in the first preview (shader compiles and first dispatches).
"""
from __future__ import annotations

import json
import os
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENES = ("cornell_box", "columned_hall", "textured_room", "emissive_room", "hdri_courtyard",
          "sky_courtyard", "metal_room", "city", "diorama")
SIZES = ((160, 120), (640, 480))
LABELS = {"cornell_box": "Cornell box (area light)", "columned_hall": "columned hall (sun)",
          "textured_room": "textured room", "emissive_room": "emissive room",
          "hdri_courtyard": "HDRI courtyard (exterior)",
          "sky_courtyard": "courtyard under a uniform sky + sun",
          "metal_room": "room of metals (steel, copper, gold)",
          "city": "city block, instanced domes",
          "diorama": "imported glTF diorama (142k triangles, textured)"}
STAGE_ORDER = ("G-buffers", "radiance cache", "diffuse+AO gather", "glossy gather",
               "world glossy gather", "denoise + upsample", "direct light", "compose", "other")


def _row(scene: str, width: int, height: int, quick: bool) -> dict:
    python = ROOT / ".venv" / "bin" / "python"
    if not python.exists():
        raise RuntimeError("the bpy venv .venv is missing: run `make venv` (make bench does)")
    cmd = [str(python), str(ROOT / "tools" / "bench" / "bench_preview_blender.py"), scene,
           str(width), str(height)] + (["--quick"] if quick else [])
    with tempfile.TemporaryDirectory(prefix="voxgi-mesa-cache-") as cache:
        env = {key: value for key, value in os.environ.items()
               if key != "MESA_SHADER_CACHE_DISABLE"}
        env["MESA_SHADER_CACHE_DIR"] = cache  # empty: a new machine's first session
        row = _result(subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env),
                      "RESULT ", f"{scene} {width}×{height}")
        later = _result(subprocess.run(cmd + ["--first-only"], capture_output=True, text=True,
                                       cwd=ROOT, env=env), "FIRST ",
                        f"{scene} {width}×{height} (later session)")
    row["first_later"] = later["first"]
    return row


def _result(done, prefix: str, what: str) -> dict:
    for line in done.stdout.splitlines():
        if line.startswith(prefix):
            return json.loads(line[len(prefix):])
    raise RuntimeError(f"{what} failed:\n{done.stderr[-2000:]}")


def _goal(row) -> str:
    c16_time, c16_error = row["cycles16"]
    parts = [("error" if row["error"] <= c16_error else f"error ×{row['error'] / c16_error:.1f}"),
             ("time" if row["warm"] <= c16_time / 3 else
              f"time ×{row['warm'] / (c16_time / 3):.1f}"),
             ("cold" if row["first"] <= row["warm"] + c16_time else
              f"cold +{row['first'] - row['warm'] - c16_time:.1f} s")]
    met = all(" " not in p for p in parts)
    goal = "met" if met else "; ".join(p if " " in p else f"{p} met" for p in parts)
    if "first_later" in row and row["first"] > row["warm"] + c16_time:
        goal += ("; later sessions' cold met" if row["first_later"] <= row["warm"] + c16_time
                 else f"; later sessions' cold +{row['first_later'] - row['warm'] - c16_time:.1f} s")
    return goal


def run(quick: bool = False, out=print) -> str:
    scenes = ("cornell_box",) if quick else SCENES
    sizes = ((80, 60),) if quick else SIZES
    rows, failed = [], []
    for width, height in sizes:
        for scene in scenes:
            try:
                rows.append(_row(scene, width, height, quick))
            except RuntimeError as exc:
                failed.append(str(exc))
                out(f"**{scene} {width}×{height} failed** (the section goes on): "
                    f"{str(exc)[-600:]}\n")
    lines = ["### Preview vs Cycles 16 / 64 spp + OIDN: first preview on a new "
             "machine and in a later session, warm preview (median, radiance cache rebuilt), Combined relative L1 "
             "against Cycles at its default light paths" +
             (" — quick: a check of the tooling, not the measurement" if quick else ""), "",
             "| scene | size | triangles | VoxGI first | first, later session | VoxGI warm "
             "| error | Cycles 16 + OIDN "
             "| Cycles 64 + OIDN | warm ÷ C16 | goal (error ≤ C16's, warm ≤ ⅓ C16, first ≤ "
             "warm + C16) | reference | two references apart | against their mean: "
             "VoxGI / C16 / C64 |",
             "|---|---|---:|---:|---:|---:|---:|---|---|---:|---|---|---:|---|"]
    for row in rows:
        c16, c64 = row["cycles16"], row["cycles64"]
        lines.append(
            f"| {LABELS.get(row['scene'], row['scene'])} | {row['width']}×{row['height']} | "
            f"{row['triangles']:,} | {row['first']:.2f} s | {row['first_later']:.2f} s | "
            f"{row['warm']:.2f} s | "
            f"{row['error']:.3f} | {c16[0]:.2f} s, {c16[1]:.3f} | {c64[0]:.2f} s, {c64[1]:.3f} | "
            f"{row['warm'] / c16[0]:.1f} | {_goal(row)} | {row['reference']} | "
            f"{row['reference_noise']:.3f} | {row['against_both']['voxgi']:.3f} / "
            f"{row['against_both']['cycles16']:.3f} / {row['against_both']['cycles64']:.3f} |")
    lines += ["", "### Where a warm preview's time goes, against the floor: "
              "each stage's dispatches timed to completion; floor = its rays at the ray rate "
              "and its texel fetches at the fetch rate that trivial kernels reach on the same "
              "BVH in the same process; first extra = what the stage cost more in the first "
              "preview (shader compiles, first dispatches)", "",
              "| scene | size | stage | time | rays | fetches | floor | time ÷ floor "
              "| first extra |", "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        stages = row["stages"]
        where = f"{LABELS.get(row['scene'], row['scene'])} | {row['width']}×{row['height']}"
        for stage in sorted(stages, key=lambda s: STAGE_ORDER.index(s)
                            if s in STAGE_ORDER else len(STAGE_ORDER)):
            s = stages[stage]
            ratio = f"{s['seconds'] / s['floor']:.1f}" if s["floor"] > 0 else "—"
            lines.append(f"| {where} | {stage} | {s['seconds'] * 1000:.0f} ms | "
                         f"{s['rays'] / 1e6:.2f} M | {s['fetches'] / 1e6:.1f} M | "
                         f"{s['floor'] * 1000:.0f} ms | {ratio} | "
                         f"{max(s['first'] - s['seconds'], 0.0) * 1000:.0f} ms |")
        traced = sum(s["seconds"] for s in stages.values())
        lines.append(f"| {where} | **all stages** | {traced * 1000:.0f} ms | "
                     f"{sum(s['rays'] for s in stages.values()) / 1e6:.2f} M | "
                     f"{sum(s['fetches'] for s in stages.values()) / 1e6:.1f} M | "
                     f"{sum(s['floor'] for s in stages.values()) * 1000:.0f} ms | "
                     f"{traced / max(sum(s['floor'] for s in stages.values()), 1e-9):.1f} | "
                     f"shaders created: {row['compiles']} in {row['compile_seconds']:.2f} s |")
    lines += ["", "| scene | size | closest-hit rays/s | any-hit rays/s | texel fetches/s |",
              "|---|---|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {LABELS.get(row['scene'], row['scene'])} | {row['width']}×"
                     f"{row['height']} | {row['closest_rate'] / 1e6:.2f} M | "
                     f"{row['any_rate'] / 1e6:.2f} M | {row['fetch_rate'] / 1e6:.0f} M |")
    table = "\n".join(lines)
    out(table + "\n")
    if failed:
        raise RuntimeError("; ".join(f.splitlines()[0] for f in failed))
    return table

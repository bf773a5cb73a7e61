"""Bench section "probes", the three.js reader (docs/web_reader.md): load-to-first-frame time of
web/index.html in headless Chromium (Debian's, WebGL2 on SwiftShader: no GPU here) for the
Cornell box and the thin-wall rooms exported by Blender with their probes
(tests/blender/gltf_probe_scenes.py, run with the bpy venv .venv), with the plugin and without
(probes=off), median of 5 runs (2 with --quick), each in a fresh browser context (empty cache).

Times are from the navigation's start: "loaded" when GLTFLoader and the plugin are done (the
page's modules fetched and parsed, the .glb fetched and parsed, the probes read, checked and
packed), "first frame" when the first frame has been drawn and read back (shaders compiled).
"""
from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "web"))
from browser import Browser, chromium_version  # noqa: E402

SCENES = ("box", "thin_wall")
SIZE = (640, 480)


def _export(directory: Path) -> dict[str, Path]:
    python = ROOT / ".venv" / "bin" / "python"
    if not python.exists():
        raise RuntimeError("the bpy venv .venv is missing: run `make venv` (make bench does)")
    done = subprocess.run([str(python), str(ROOT / "tests" / "blender" / "gltf_probe_scenes.py"),
                           str(directory), "--no-preview"], capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"gltf_probe_scenes.py failed:\n{done.stderr[-2000:]}")
    return {name: directory / f"{name}.glb" for name in SCENES}


def _times(browser: Browser, path: Path, runs: int, **params) -> tuple[float, float]:
    """Median (loaded, first frame) in ms over ``runs`` fresh page loads."""
    url = browser.serve_file(path)
    loaded, first = [], []
    for _ in range(runs):
        state = browser.open(browser.page_url(url, width=SIZE[0], height=SIZE[1], **params), *SIZE)
        if state["state"] != "ready" or state["probeErrors"]:
            raise RuntimeError(f"{path.name}: {state['error'] or state['probeErrors']}")
        loaded.append(state["timings"]["loaded"])
        first.append(state["timings"]["firstFrame"])
    return statistics.median(loaded), statistics.median(first)


def run(quick: bool = False, out=print) -> str:
    runs = 2 if quick else 5
    with tempfile.TemporaryDirectory(prefix="voxgi-web-bench-") as tmp:
        files = _export(Path(tmp))
        rows = []
        with Browser() as browser:
            for name, path in files.items():
                loaded, first = _times(browser, path, runs)
                probes = browser.eval("(() => { const l = window.voxgi.lighting; return l ? "
                                    "l.volumes.reduce((n, v) => n + v.probeCount, 0) : 0; })()")
                off_loaded, off_first = _times(browser, path, runs, probes="off")
                rows.append(f"| {name}.glb | {path.stat().st_size / 1024:.1f} | {probes} | {loaded:.0f} | "
                            f"{first:.0f} | {off_loaded:.0f} | {off_first:.0f} |")
    table = "\n".join([
        f"### three.js reader: load to first frame ({SIZE[0]}×{SIZE[1]}, {chromium_version()}, "
        f"WebGL2 on SwiftShader, median of {runs})",
        "",
        "| file | KiB | probes | loaded, ms | first frame, ms | loaded, probes=off | first frame, probes=off |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *rows, ""])
    out(table)
    return table


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)

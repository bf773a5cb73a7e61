"""Validate and build the installable extension zip with Blender's own builder.

The builder ships inside the bpy wheel (``addons_core/bl_pkg/cli/blender_ext.py``); it reads
``blender_manifest.toml`` and honours its ``[build] paths_exclude_pattern``.
Usage: ``python tools/build_extension.py --output-dir dist`` → prints the zip's path.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def blender_ext_script() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("bpy is not installed in this Python; run `make test` or `make venv` first")
    bpy_dir = Path(spec.origin).parent
    scripts = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not scripts:
        raise SystemExit(f"Blender's extension builder was not found under {bpy_dir}")
    return scripts[-1]


def build(output_dir: Path) -> Path:
    """Validate the manifest and build the zip into ``output_dir``; return the zip path."""
    script = blender_ext_script()
    output_dir.mkdir(parents=True, exist_ok=True)
    for old in output_dir.glob("voxgi-*.zip"):
        old.unlink()
    subprocess.run([sys.executable, str(script), "validate", str(ROOT)], check=True)
    subprocess.run([sys.executable, str(script), "build", "--source-dir", str(ROOT),
                    "--output-dir", str(output_dir)], check=True)
    zips = sorted(output_dir.glob("voxgi-*.zip"), key=os.path.getmtime)
    if not zips:
        raise SystemExit("the extension builder produced no zip")
    return zips[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", default=str(ROOT / "dist"))
    args = parser.parse_args()
    print(build(Path(args.output_dir)))


if __name__ == "__main__":
    main()

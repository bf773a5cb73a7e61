"""Helpers shared by the benchmark sections (dev-only; see tools/bench/bench.py)."""
from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ENGINE = "voxgi_addon"


def engine_module(name: str):
    """Import ``voxgi_addon.<name>`` without Blender.

    The engine is numpy-only, but the add-on package's ``__init__`` may import ``bpy`` (which
    the bench venv does not have). In that case the package is stood in by a bare namespace
    module over the same folder, so its engine submodules still import with their relative
    imports.
    """
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    try:
        importlib.import_module(ENGINE)
    except ImportError as exc:
        if getattr(exc, "name", None) not in ("bpy", "mathutils", "gpu", "bmesh"):
            raise
        for key in [k for k in sys.modules if k == ENGINE or k.startswith(ENGINE + ".")]:
            del sys.modules[key]
        pkg = types.ModuleType(ENGINE)
        pkg.__path__ = [str(ROOT / ENGINE)]
        sys.modules[ENGINE] = pkg
    return importlib.import_module(f"{ENGINE}.{name}")

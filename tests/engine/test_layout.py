"""The layout's import rules (README "Layout"), checked on every module's source.

Imports run one way: ``ui``/``operators`` → ``render`` → ``blender`` → ``voxgi_addon``. The
engine (``voxgi_addon/``) never imports Blender's modules; nothing below ``render`` imports
``operators``/``render``; ``ui`` is imported only by registration; ``operators/`` holds
operators only; the tests import the engine under one name (``voxgi.voxgi_addon``).
Every import statement counts, including those inside functions.
"""
from __future__ import annotations

import ast
import pathlib

import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGES = ("voxgi_addon", "blender", "render", "operators", "ui")
BLENDER_MODULES = {"bpy", "gpu", "bmesh", "mathutils", "gpu_extras", "bpy_extras", "bl_math", "aud"}
REGISTRATION = {"", "registration"}  # the root __init__ and registration.py
# Package → the add-on packages it may import (besides itself).
ALLOWED = {
    "voxgi_addon": set(),
    "blender": {"voxgi_addon"},
    "render": {"blender", "voxgi_addon"},
    "operators": {"render", "blender", "voxgi_addon"},
    "ui": {"operators", "render", "blender", "voxgi_addon"},
}


def module_name(path: pathlib.Path) -> str:
    """Dotted name inside the add-on ('' for the root ``__init__``)."""
    parts = list(path.relative_to(REPO_ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def addon_modules() -> dict[str, str]:
    """Add-on module name → source, for every module that ships in the extension."""
    sources = {}
    for path in sorted(REPO_ROOT.glob("*.py")):
        sources[module_name(path)] = path.read_text()
    for package in PACKAGES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            sources[module_name(path)] = path.read_text()
    return sources


def imported_modules(name: str, source: str, is_package: bool) -> set[str]:
    """Absolute dotted names imported anywhere in ``source`` (relative imports resolved
    against module ``name``; ``from . import x`` yields ``pkg.x``)."""
    package = name.split(".") if is_package else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1] if node.level > 1 else package
                stem = ".".join([*base, *([node.module] if node.module else [])])
                found.add(stem)
                found.update(f"{stem}.{alias.name}" if stem else alias.name for alias in node.names)
            else:
                found.add(node.module)
    return found


def violations(sources: dict[str, str], packages: set[str]) -> list[str]:
    """Rule breaks among ``sources`` (module name → source); ``packages`` are module names that
    are packages (``__init__``)."""
    problems = []
    for name, source in sources.items():
        top = name.split(".")[0]
        for target in imported_modules(name, source, name in packages):
            target_top = target.split(".")[0]
            if top == "voxgi_addon" and target_top in BLENDER_MODULES:
                problems.append(f"engine module {name} imports {target}")
            if target_top == "ui" and name not in REGISTRATION and top != "ui":
                problems.append(f"{name} imports {target}: ui/ is imported only by registration")
            if top in ALLOWED and target_top in ALLOWED and target_top != top \
                    and target_top not in ALLOWED[top] and target_top != "ui":
                problems.append(f"{name} ({top}/) imports {target} ({target_top}/): imports run "
                                "ui/operators → render → blender → voxgi_addon")
    return problems


def package_names(sources) -> set[str]:
    return {name for name in sources if name == "" or (REPO_ROOT / name.replace(".", "/")).is_dir()}


def test_imports_run_one_way():
    sources = addon_modules()
    assert len(sources) > 60  # the walk found the tree
    assert violations(sources, package_names(sources)) == []


@pytest.mark.parametrize("name, source, complaint", [
    ("voxgi_addon.gi.fake", "import bpy\n", "engine module voxgi_addon.gi.fake imports bpy"),
    ("voxgi_addon.gi.fake", "def f():\n    from gpu.types import GPUTexture\n", "imports gpu.types"),
    ("voxgi_addon.fake", "from ..operators import voxelize\n", "imports operators"),
    ("blender.fake", "from ..render import pipeline\n", "imports render"),
    ("blender.snapshot.fake", "from ...operators.voxelize import x\n", "imports operators.voxelize"),
    ("render.fake", "from ..operators import update\n", "imports operators"),
    ("operators.fake", "from ..ui import panel\n", "ui/ is imported only by registration"),
    ("render.fake", "from ..ui.panel import VOXGI_PT_main\n", "ui/ is imported only by registration"),
])
def test_the_rules_catch_what_they_forbid(name, source, complaint):
    problems = violations({name: source}, set())
    assert any(complaint in p for p in problems), problems


def test_registration_may_import_ui():
    assert violations({"": "from . import blender, operators, render, ui\n"}, {""}) == []


def test_operator_modules_define_operators():
    """``operators/`` keeps only operators: every module defines an Operator subclass."""
    for path in sorted((REPO_ROOT / "operators").glob("*.py")):
        if path.name == "__init__.py":
            continue
        tree = ast.parse(path.read_text())
        bases = [ast.unparse(b) for node in ast.walk(tree) if isinstance(node, ast.ClassDef)
                 for b in node.bases]
        assert any(b.endswith("Operator") for b in bases), f"{path.name} defines no operator"


def test_tests_import_the_engine_under_one_name():
    """Tests and tools reach the engine as ``voxgi.voxgi_addon`` only (one module object)."""
    offenders = []
    for path in sorted((REPO_ROOT / "tests").rglob("*.py")):
        for target in imported_modules("tests.x", path.read_text(), False):
            if target == "voxgi_addon" or target.startswith("voxgi_addon."):
                offenders.append(f"{path.relative_to(REPO_ROOT)} imports {target}")
    assert offenders == []

"""The extension as users get it: build the zip, install it into a fresh Blender, voxelize.

A subprocess (fresh ``python`` with bpy) installs the zip with
``extensions.package_install_files`` into a user config that lives in ``tmp_path`` (HOME,
XDG_* and every ``BLENDER_USER_*`` Blender 5.0 honours point there), so the installed
``bl_ext.user_default.voxgi`` — not the repository — runs ``voxgi.voxelize``. Its per-mesh
voxel counts must equal what the engine computes here for the same triangles.
"""
from __future__ import annotations

import importlib
import importlib.util
import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap
import zipfile

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
RESULT_PREFIX = "VOXGI_RESULT "
SPAN = 0.25
CASCADES = 3
# A 2 m cube is a one-voxel shell at each span: (n+1)³ − (n−1)³ with n = 2 m / span.
CUBE_COUNTS = [9**3 - 7**3, 5**3 - 3**3, 3**3 - 1**3]  # 386, 98, 26

INSTALL_SCRIPT = textwrap.dedent(
    """
    import importlib, json, pathlib, sys
    import bpy

    zip_path, geometry_path, extensions_dir = sys.argv[1:4]
    assert "voxgi" not in sys.modules
    status = bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    assert status == {"FINISHED"}, status
    assert hasattr(bpy.ops.voxgi, "voxelize"), "voxgi.voxelize is not registered"
    package = importlib.import_module("bl_ext.user_default.voxgi")
    installed_at = pathlib.Path(package.__file__).resolve().parent
    assert installed_at.is_relative_to(pathlib.Path(extensions_dir).resolve()), installed_at

    # Not read_factory_settings: factory preferences would disable the installed extension.
    bpy.ops.wm.read_homefile(use_empty=True)
    assert hasattr(bpy.context.scene, "voxgi")
    for name, shape in json.loads(pathlib.Path(geometry_path).read_text()).items():
        mesh = bpy.data.meshes.new(name + " Mesh")
        mesh.from_pydata(shape["vertices"], [], shape["triangles"])
        mesh.update()
        obj = bpy.data.objects.new(name, mesh)
        obj.location = shape["location"]
        bpy.context.scene.collection.objects.link(obj)
    settings = bpy.context.scene.voxgi
    settings.span_mode = "MANUAL"
    settings.base_span, settings.cascade_count = float(sys.argv[4]), int(sys.argv[5])
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}

    session = importlib.import_module("bl_ext.user_default.voxgi.blender.session")
    caches = session.scene_session(bpy.context.scene.name_full).caches
    print("VOXGI_RESULT " + json.dumps({
        "installed_at": str(installed_at),
        "cascades": [s.voxel_count for s in caches.cascade_stats],
        "spans": [s.span for s in caches.cascade_stats],
        "meshes": {key: [c.voxel_count if c is not None else None for c in cs]
                   for key, cs in caches.caches.items()},
        "warnings": list(caches.warnings), "skipped": [str(s) for s in caches.skipped],
    }))
    """
)


def _build_zip(output_dir):
    spec = importlib.util.spec_from_file_location(
        "voxgi_build_extension", REPO_ROOT / "tools" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(output_dir)


def _cube(size=2.0):
    h = size / 2
    vertices = [(x, y, z) for z in (-h, h) for y in (-h, h) for x in (-h, h)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return np.array(vertices, float), np.array(triangles)


def _uv_sphere(radius=0.7, segments=12, rings=7):
    """A UV sphere as explicit triangles (so no triangulation choice is left to Blender)."""
    vertices = [(0.0, 0.0, radius)]
    for r in range(1, rings):
        theta = math.pi * r / rings
        vertices += [(radius * math.sin(theta) * math.cos(2 * math.pi * s / segments),
                      radius * math.sin(theta) * math.sin(2 * math.pi * s / segments),
                      radius * math.cos(theta)) for s in range(segments)]
    vertices.append((0.0, 0.0, -radius))
    bottom = len(vertices) - 1

    def ring(r, s):
        return 1 + (r - 1) * segments + s % segments

    triangles = [(0, ring(1, s), ring(1, s + 1)) for s in range(segments)]
    for r in range(1, rings - 1):
        for s in range(segments):
            a, b, c, d = ring(r, s), ring(r + 1, s), ring(r + 1, s + 1), ring(r, s + 1)
            triangles += [(a, b, c), (a, c, d)]
    triangles += [(ring(rings - 1, s + 1), ring(rings - 1, s), bottom) for s in range(segments)]
    return np.array(vertices, float), np.array(triangles)


def _subprocess_env(tmp_path):
    """The environment of a Blender whose whole user config lives in ``tmp_path``."""
    home = tmp_path / "home"
    env = dict(os.environ, HOME=str(home), XDG_CONFIG_HOME=str(home / ".config"),
               XDG_CACHE_HOME=str(home / ".cache"), PYTHONNOUSERSITE="1")
    env.pop("PYTHONPATH", None)
    for kind in ("RESOURCES", "CONFIG", "SCRIPTS", "EXTENSIONS", "DATAFILES"):
        env[f"BLENDER_USER_{kind}"] = str(home / "blender" / kind.lower())
    return env


def test_built_zip_installs_and_voxelizes_like_the_engine(voxgi, tmp_path):
    zip_path = _build_zip(tmp_path / "dist")
    archive = zipfile.ZipFile(zip_path)
    names = archive.namelist()
    assert "blender_manifest.toml" in names and "operators/voxelize.py" in names
    leaked = [n for n in names if n.split("/")[0] in {"tests", "tools", ".ci", "Makefile", "docs", ".venv"}
              or n.startswith("requirements") or n == "ruff.toml"]
    assert not leaked, f"development files in the extension zip: {leaked}"
    # No test harness either: nothing that imports pytest or renders Cycles references.
    harness = [n for n in names if n.endswith(".py") and any(
        marker in archive.read(n) for marker in (b"import pytest", b"render_cycles_passes", b"cycles_passes"))]
    assert not harness, f"test harness code in the extension zip: {harness}"

    shapes = {"Cube": (*_cube(2.0), (0.0, 0.0, 1.0)), "Sphere": (*_uv_sphere(), (3.0, 0.5, 0.7))}
    geometry = tmp_path / "geometry.json"
    geometry.write_text(json.dumps({
        name: {"vertices": v.tolist(), "triangles": t.tolist(), "location": list(loc)}
        for name, (v, t, loc) in shapes.items()}))
    script = tmp_path / "install_and_voxelize.py"
    script.write_text(INSTALL_SCRIPT)
    env = _subprocess_env(tmp_path)
    proc = subprocess.run(
        [sys.executable, str(script), str(zip_path), str(geometry), env["BLENDER_USER_EXTENSIONS"],
         str(SPAN), str(CASCADES)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    lines = [line for line in proc.stdout.splitlines() if line.startswith(RESULT_PREFIX)]
    assert proc.returncode == 0 and len(lines) == 1, (
        f"installing/running the extension failed (exit {proc.returncode})\n"
        f"--- stdout ---\n{proc.stdout[-4000:]}\n--- stderr ---\n{proc.stderr[-4000:]}")
    result = json.loads(lines[0][len(RESULT_PREFIX):])

    voxelize = importlib.import_module("voxgi.voxgi_addon.voxelize.surface")
    spans = [SPAN * 2**i for i in range(CASCADES)]
    expected = {f"{name} Mesh": [voxelize.voxelize_triangles(v, t, span).voxel_count for span in spans]
                for name, (v, t, _) in shapes.items()}
    assert expected["Cube Mesh"] == CUBE_COUNTS
    assert result["spans"] == spans
    assert result["meshes"] == expected
    assert result["cascades"] == [sum(c[i] for c in expected.values()) for i in range(CASCADES)]
    assert result["warnings"] == [] and result["skipped"] == []

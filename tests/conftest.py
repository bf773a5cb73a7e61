"""Shared test settings.

* The repository root is the add-on package; both lanes import it under ONE name, ``voxgi``
  (as Blender imports an installed extension under its package name): a symlink ``voxgi`` →
  repository root in a temporary directory on ``sys.path``. ``voxgi/__init__.py`` imports bpy
  only when registering, so the engine lane (``voxgi.voxgi_addon``) runs without Blender.
* hypothesis runs derandomized under CI so a run is reproducible.
"""
import atexit
import os
import pathlib
import shutil
import sys
import tempfile

from hypothesis import settings

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]

_package_dir = tempfile.mkdtemp(prefix="voxgi-pkg-")
(pathlib.Path(_package_dir) / "voxgi").symlink_to(REPO_ROOT, target_is_directory=True)
sys.path.insert(0, _package_dir)
atexit.register(shutil.rmtree, _package_dir, ignore_errors=True)

settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

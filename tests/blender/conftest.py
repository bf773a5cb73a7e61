"""Blender-lane fixtures: the repository imported as the add-on package ``voxgi``.

The add-on installs as ``bl_ext.user_default.voxgi``; here the repository root is importable
as ``voxgi`` (``tests/conftest.py``), so the add-on's relative imports work exactly as they do
when installed.
"""
from __future__ import annotations

import importlib
import pathlib

import bpy
import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def voxgi():
    """The registered add-on package; unregistered after the session."""
    package = importlib.import_module("voxgi")
    package.register()
    try:
        yield package
    finally:
        if hasattr(bpy.types.Scene, "voxgi"):
            package.unregister()


@pytest.fixture(autouse=True)
def empty_file(voxgi):
    """Every test starts from a factory-empty file with the add-on registered."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()
    assert hasattr(bpy.context.scene, "voxgi")
    yield


@pytest.fixture
def session(voxgi):
    """The add-on's session module (reports and caches of the last operator run)."""
    return importlib.import_module("voxgi.blender.session")


@pytest.fixture
def snapshot_module(voxgi):
    """``voxgi.blender.snapshot.scene`` (``take_snapshot``)."""
    return importlib.import_module("voxgi.blender.snapshot.scene")


@pytest.fixture
def jobs(voxgi):
    """The add-on's engine-job runner (``voxgi.blender.jobs``)."""
    return importlib.import_module("voxgi.blender.jobs")


@pytest.fixture
def interactive(jobs, monkeypatch):
    """Jobs run as in a UI session; anything left running is cancelled and joined after."""
    monkeypatch.setattr(jobs, "synchronous", False)
    yield jobs
    jobs.cancel_all()
    assert jobs.wait_idle(60.0), "a job did not stop after being cancelled"

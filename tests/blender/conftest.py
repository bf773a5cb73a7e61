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


def one_bounce_by_default() -> None:
    """Scenes of the tests start at Bounces = 1 (Manual) instead of following Cycles' Light
    Paths: the tests written before the multi-bounce cache compare with one-bounce Cycles
    references and keep their limits; tests of several bounces set ``bounce_source`` back to
    'CYCLES' (test_multibounce.py). Patches the property defaults before registration."""
    settings = importlib.import_module("voxgi.blender.settings").VoxGISceneSettings
    annotations = settings.__annotations__
    for name, default in (("bounce_source", "MANUAL"), ("bounces", 1)):
        prop = annotations[name]
        annotations[name] = prop.function(**{**prop.keywords, "default": default})


@pytest.fixture(scope="session")
def voxgi():
    """The registered add-on package (one bounce by default, ``one_bounce_by_default``);
    unregistered after the session."""
    package = importlib.import_module("voxgi")
    one_bounce_by_default()
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

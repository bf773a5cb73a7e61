"""The add-on session: per-scene results that must stay out of ID properties.

Big arrays (voxel caches, later octrees and probes) live here, in a module-level
Python object keyed by scene name, never in ``Scene``/``Object`` ID properties
(they would be saved into the .blend and copied on undo). The session is
cleared when a file is loaded and when the add-on is unregistered.

Only the main thread reads or writes the session.
"""
from __future__ import annotations

import atexit
from dataclasses import dataclass, field
from typing import Any

import bpy

# Report levels used by operators, in the order a panel would show them.
REPORT_LEVELS = ("ERROR", "WARNING", "INFO")


@dataclass
class SceneSession:
    """What the add-on remembers about one scene between operator runs.

    snapshot_summary : counts describing the last snapshot (objects, meshes,
        triangles, ...), or None before the first run.
    caches : the last ``build_scene_caches`` result in use (voxel caches per mesh and
        cascade, stats, timings), or None.
    span_caches : the recent caches of other base spans, most recently used last (Auto mode
        switches span as the view changes; caches of a span come back when the view does).
    view_fit : the last ``view_fit.ViewFit`` (Auto mode), the next fit's hysteresis.
    timings : seconds per stage of the last run, snapshot included.
    last_report : (level, message) lines the last operator run reported, level in
        ``REPORT_LEVELS``; kept so tests and the panel can read them in background mode.
    """

    snapshot_summary: dict[str, int] | None = None
    caches: Any = None
    span_caches: list = field(default_factory=list)
    view_fit: Any = None
    timings: dict[str, float] = field(default_factory=dict)
    last_report: list[tuple[str, str]] = field(default_factory=list)
    gi_state: Any = None  # voxgi_addon.gi_update.GIState of the last update
    gi_timings: dict[str, float] = field(default_factory=dict)
    gpu_volume: Any = None  # render.gpu_volume.GPUVolume: the octree atlas on the GPU
    tracer_used: str = ""   # "GPU" or "numpy": who traced the last preview
    snapshot: Any = None    # the last render's SceneSnapshot (world, camera, Film › Transparent)
    probes: Any = None      # list[voxgi_addon.probes.grid.ProbeGrid], see blender/probe_store.py


_sessions: dict[str, SceneSession] = {}


def scene_session(scene_name: str) -> SceneSession:
    """The session of the scene named ``scene_name`` (``Scene.name_full``), created on first use."""
    session = _sessions.get(scene_name)
    if session is None:
        session = _sessions[scene_name] = SceneSession()
    return session


def peek_session(scene_name: str) -> SceneSession | None:
    """The session of a scene if one exists, without creating it (for drawing code)."""
    return _sessions.get(scene_name)


def clear_sessions() -> None:
    """Forget every scene's results (file load, unregister)."""
    _sessions.clear()


@bpy.app.handlers.persistent
def _clear_on_load(*_args) -> None:
    # Results belong to the file they were computed from.
    clear_sessions()


classes = ()


def register() -> None:
    if _clear_on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_clear_on_load)
    # As the bpy module, Blender never unregisters add-ons at exit, and this module outlives
    # Python's shutdown (the handler above and registered classes reach it), so a session's
    # GPUVolume textures would never be freed: "Not freed memory blocks" at exit. atexit runs
    # last-registered first, so this runs before bpy's own exit handler frees the GPU
    # (docs/gi_pipeline.md, "GPU resources at exit").
    atexit.unregister(clear_sessions)
    atexit.register(clear_sessions)


def unregister() -> None:
    atexit.unregister(clear_sessions)
    if _clear_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_clear_on_load)
    clear_sessions()

"""The preview pipeline shared by F12 (``engine.py``) and ``voxgi.render_preview``.

``render_scene_passes``: snapshot (main thread) → the session's voxel caches (voxelizing when
there are none or the spans changed) → one GI update → the camera's Cycles-named passes, traced
on the GPU when it can (``gpu_preview``) and with the numpy tracer otherwise, with a report line
saying which and why.
"""
from __future__ import annotations

import time

from ..blender.reports import timing_text
from ..blender.session import scene_session
from ..blender.settings import cone_settings, gi_settings
from ..blender.snapshot import snapshot_or_error
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.update import update_gi
from ..voxgi_addon.preview.passes import render_passes
from ..voxgi_addon.voxelize.scene_caches import build_scene_caches
from . import gpu_context


def caches_for(context, snapshot, scene=None):
    """The session's caches, voxelizing now when there are none or the spans changed."""
    scene = scene or context.scene
    settings = scene.voxgi
    session = scene_session(scene.name_full)
    caches = session.caches
    spans_match = caches is not None and len(caches.cascade_stats) == settings.cascade_count and \
        abs(caches.cascade_stats[0].span - settings.base_span) < 1e-9
    missing = caches is not None and any(o.name not in caches.bindings for o in snapshot.objects)
    if not spans_match or missing:
        caches = build_scene_caches(snapshot, settings.base_span, settings.cascade_count)
        session.caches = caches
    return caches


def trace_passes(scene, snapshot, state, width, height):
    """(passes, timings, report lines): the GPU tracer when the scene's tracer setting allows
    and a GPU context can be had, else the numpy tracer with a line saying why."""
    settings = scene.voxgi
    cones = cone_settings(settings)
    session = scene_session(scene.name_full)
    why = "the scene's tracer setting is numpy"
    if settings.tracer == "AUTO":
        ready, why = gpu_context.ensure_gpu_context()
        if ready:
            try:
                from .gpu_preview import render_passes_gpu
                from .gpu_volume import GPUVolume
                session.gpu_volume = session.gpu_volume or GPUVolume()
                passes, timings = render_passes_gpu(snapshot, state, width, height, cones,
                                                    settings.light_samples, session.gpu_volume,
                                                    shadows=settings.shadows,
                                                    gi_stride=int(settings.gi_resolution))
                session.tracer_used = "GPU"
                return passes, timings, [("INFO", "VoxGI: cones traced on the GPU")]
            except VoxGIError:
                raise
            except Exception as error:  # shader creation or dispatch failed: fall back
                session.gpu_volume = None
                why = f"the GPU tracer failed: {error}"
    passes, timings = render_passes(snapshot, state, width, height, cones,
                                    light_samples=settings.light_samples, shadows=settings.shadows,
                                    gi_stride=int(settings.gi_resolution))
    session.tracer_used = "numpy"
    return passes, timings, [("WARNING" if settings.tracer == "AUTO" else "INFO",
                              f"VoxGI: numpy tracer used ({why})")]


def render_scene_passes(context, scene, depsgraph, width, height, indirect_source=None):
    """Snapshot, update and trace ``scene``'s camera view: (passes, report lines).
    indirect_source : 'CONES' or 'PROBES' (None: the scene's ``indirect_source`` setting).
    Raises VoxGIError for scenes that cannot be rendered."""
    if scene.camera is None:
        raise VoxGIError("the scene has no camera to render the preview from")
    start = time.perf_counter()
    snapshot, snap_seconds = snapshot_or_error(context, depsgraph)
    caches = caches_for(context, snapshot, scene)
    state = update_gi(snapshot, caches, gi_settings(scene.voxgi))
    passes, render_timings, lines = trace_passes(scene, snapshot, state, width, height)
    if (indirect_source or scene.voxgi.indirect_source) == "PROBES":
        from .probe_preview import apply_probe_indirect
        seconds, line = apply_probe_indirect(scene, snapshot, passes, width, height)
        render_timings["probes"] = seconds
        lines.append(line)
    session = scene_session(scene.name_full)
    session.gi_state = state
    session.gi_timings = {"snapshot": snap_seconds, **state.timings, **render_timings,
                          "total": time.perf_counter() - start}
    lines.append(("INFO", timing_text(session.gi_timings)))
    return passes, lines

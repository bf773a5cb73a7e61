"""The preview pipeline shared by F12 (``engine.py``) and ``voxgi.render_preview``.

``render_scene_passes``: snapshot (main thread) → for Fast quality (cone tracing) the voxel
scene: in Auto mode the view fit (span, resolution and centre of the cascades,
docs/gi_pipeline.md "View-fitted cascades"), the session's voxel caches of that span
(voxelizing when there are none) and one GI update → the camera's Cycles-named passes, traced
on the GPU when it can (``gpu_preview``) and with the numpy tracer otherwise, with report
lines saying which tracer and why, and what each cascade covers. Accurate quality (the
default) traces the scene's triangles for every pass, so it builds no voxels at all: the
session keeps the last voxel state for the debug views and probes.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..blender.reports import coverage_lines, timing_text
from ..blender.session import scene_session
from ..blender.settings import cone_settings, fit_settings, gi_settings, gi_stride, is_auto, trace_options
from ..blender.snapshot import snapshot_or_error
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.update import update_gi
from ..voxgi_addon.gi.view_fit import cascade_shares, fit_view, probe_view
from ..voxgi_addon.preview.passes import PASS_NAMES, render_passes
from ..voxgi_addon.preview.region import traced_rect
from ..voxgi_addon.scene.camera import camera_view, check_camera_type
from ..voxgi_addon.scene.view_camera import crop_camera
from ..voxgi_addon.voxelize.scene_caches import build_scene_caches
from . import gpu_context

MAX_SPAN_CACHES = 3  # base spans whose voxel caches the session keeps


def view_fit_for(scene, snapshot):
    """Auto mode: the view-fitted cascades (the session's last fit gives hysteresis), kept in
    the session; Manual: None. Raises VoxGIError for a scene without triangles."""
    session = scene_session(scene.name_full)
    if not is_auto(scene.voxgi):
        session.view_fit = None
        return None
    session.view_fit = fit_view(snapshot, fit_settings(scene.voxgi), previous=session.view_fit)
    return session.view_fit


def _spans_match(caches, base_span, count) -> bool:
    return caches is not None and len(caches.cascade_stats) == count and \
        abs(caches.cascade_stats[0].span - base_span) < 1e-9


def caches_for(context, snapshot, scene=None, fit=None):
    """The session's caches for the fitted span (``fit``) or the manual base span, reusing the
    caches of that span when the session has them and voxelizing otherwise (or when objects
    were added). Keeps up to ``MAX_SPAN_CACHES`` spans (docs/gi_pipeline.md "View-fitted
    cascades")."""
    scene = scene or context.scene
    settings = scene.voxgi
    session = scene_session(scene.name_full)
    base_span, count = (fit.base_span, fit.cascade_count) if fit is not None else \
        (settings.base_span, settings.cascade_count)
    known = [c for c in (*session.span_caches, session.caches) if c is not None]
    caches = pick_caches(known, snapshot, base_span, count)
    keep_caches(session, caches)
    return caches


def pick_caches(known, snapshot, base_span, count):
    """The newest of ``known`` caches of that span and count binding every object of
    ``snapshot``, else new ones voxelized (engine code: safe on the worker)."""
    caches = next((c for c in reversed(known) if _spans_match(c, base_span, count)), None)
    if caches is None or any(o.name not in caches.bindings for o in snapshot.objects):
        caches = build_scene_caches(snapshot, base_span, count)
    return caches


def keep_caches(session, caches) -> None:
    """Make ``caches`` the session's current ones, keeping up to ``MAX_SPAN_CACHES`` spans."""
    known = [c for c in (*session.span_caches, session.caches) if c is not None]
    stats = caches.cascade_stats
    kept = []
    for c in known:  # other spans, each once (by identity), oldest first
        if not _spans_match(c, stats[0].span, len(stats)) and all(c is not k for k in kept):
            kept.append(c)
    session.span_caches = [*kept, caches][-MAX_SPAN_CACHES:]
    session.caches = caches


def refit_on_worker(scene, snapshot):
    """Auto mode after a first fit: what the worker needs to fit the view again
    (``refitted_inputs``), so that an update's main-thread share is its snapshot
    (docs/gi_pipeline.md "Posed updates": the probe rays alone cost tens of ms); None in
    Manual mode or before any fit (``gi_inputs`` then, on the main thread)."""
    session = scene_session(scene.name_full)
    if not is_auto(scene.voxgi) or session.view_fit is None:
        return None
    known = tuple(c for c in (*session.span_caches, session.caches) if c is not None)
    return known, fit_settings(scene.voxgi), session.view_fit, gi_settings(scene.voxgi)


def refitted_inputs(snapshot, known, settings, previous, gi):
    """``gi_inputs`` of Auto mode from ``refit_on_worker``'s values (engine code only: the
    worker runs it): (caches, GISettings, anchor, fit)."""
    fit = fit_view(snapshot, settings, previous=previous)
    caches = pick_caches(known, snapshot, fit.base_span, fit.cascade_count)
    return caches, replace(gi, resolution=fit.resolution), fit.centre, fit


def gi_inputs(context, snapshot, scene=None):
    """(caches, GISettings, anchor, fit) of one GI update: in Auto mode the fitted span,
    resolution and centre, in Manual the scene's settings and the camera anchor (None)."""
    scene = scene or context.scene
    fit = view_fit_for(scene, snapshot)
    caches = caches_for(context, snapshot, scene, fit)
    settings = gi_settings(scene.voxgi)
    if fit is None:
        return caches, settings, None, None
    return caches, replace(settings, resolution=fit.resolution), fit.centre, fit


def view_shares(snapshot, grids, fit=None):
    """Share of the visible points per cascade (``view_fit.cascade_shares``) for the report:
    the fit's probe in Auto mode, a probe of the view in Manual; None if it cannot be had.
    Engine code only: safe on the worker thread."""
    try:
        probe = fit.probe if fit is not None else probe_view(snapshot)
    except VoxGIError:
        return None
    return cascade_shares(probe, grids)


def trace_passes(scene, snapshot, state, width, height, frame=None):
    """(passes, timings, report lines): the GPU tracer when the scene's tracer setting allows
    and a GPU context can be had, else the numpy tracer with a line saying why.
    frame : (width, height) of the whole frame when ``width`` × ``height`` is a part of it
    (a Render Region's ``traced_rect``, its camera cropped to it): the gather's lattice is the
    whole frame's. None: the image is the whole frame."""
    settings = scene.voxgi
    options = trace_options(settings, *(frame or (width, height)), snapshot.frame)
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
                                                    volume=session.gpu_volume, **options)
                session.tracer_used = "GPU"
                how = ("exact rays" if settings.quality == "ACCURATE" else "cones")
                return passes, timings, [("INFO", f"VoxGI: {how} traced on the GPU")]
            except VoxGIError:
                raise
            except Exception as error:  # shader creation or dispatch failed: fall back
                session.gpu_volume = None
                from . import gpu_scene
                gpu_scene.release()  # what a failed update left is not trusted again
                why = f"the GPU tracer failed: {error}"
    passes, timings = render_passes(snapshot, state, width, height, cones, **options)
    session.tracer_used = "numpy"
    return passes, timings, [("WARNING" if settings.tracer == "AUTO" else "INFO",
                              f"VoxGI: numpy tracer used ({why})")]


def region_passes(passes, region, traced):
    """``passes`` of the pixels ``traced`` (x0, y0, w, h from the bottom left) cut to
    ``region``'s, which lie inside them (rows top first, as the passes')."""
    x0, y0, w, h = region
    left, top = x0 - traced[0], traced[1] + traced[3] - (y0 + h)
    return {name: np.ascontiguousarray(image[top:top + h, left:left + w])
            for name, image in passes.items()}


def empty_passes(width: int, height: int) -> dict[str, np.ndarray]:
    """The passes of an image whose camera rays see no surface: every pass and the Alpha 0
    (the film puts the world behind them: ``preview.film``)."""
    passes = {name: np.zeros((height, width, 3), np.float32) for name in PASS_NAMES}
    passes["Alpha"] = np.zeros((height, width), np.float32)
    return passes


def render_scene_passes(context, scene, depsgraph, width, height, indirect_source=None,
                        view_camera=None, region=None):
    """Snapshot, update and trace ``scene``'s camera view: (passes, report lines).
    indirect_source : 'CONES' or 'PROBES' (None: the scene's ``indirect_source`` setting).
    view_camera : (model matrix (4, 4), lens shift x) of one view of a stereo or multi-view
    render (``RenderEngine.camera_model_matrix``, ``camera_shift_x``); None: the camera's own.
    region : (x0, y0, w, h), pixels from the bottom left, of a Render Region of the
    ``width`` × ``height`` frame: the passes are that region's, traced with the filters' margin
    around it (``preview.region.traced_rect``); None: the whole frame's.
    Raises VoxGIError for scenes that cannot be rendered."""
    if scene.camera is None:
        raise VoxGIError("the scene has no camera to render the preview from")
    start = time.perf_counter()
    snapshot, snap_seconds = snapshot_or_error(context, depsgraph, allow_empty=True)
    check_camera_type(snapshot.camera)
    if view_camera is not None:
        own = scene.camera.evaluated_get(depsgraph) if depsgraph is not None else scene.camera
        snapshot = replace(snapshot, camera=camera_view(
            snapshot.camera, view_camera[0], view_camera[1] - float(own.data.shift_x),
            (scene.render.pixel_aspect_x, scene.render.pixel_aspect_y)))
    session = scene_session(scene.name_full)
    # the film (preview.film) reads its world, camera and film: the region's camera, if any
    session.snapshot = snapshot if region is None else \
        replace(snapshot, camera=crop_camera(snapshot.camera, region, width, height))
    if not snapshot.objects:  # a view layer that shows no mesh: the world alone, as Cycles'
        lines = [("WARNING", w) for w in dict.fromkeys(snapshot.warnings)]
        size = (width, height) if region is None else tuple(region[2:])
        return empty_passes(*size), lines + [
            ("INFO", "VoxGI: the view layer shows no mesh: its image is the world alone")]
    voxels = {}
    state = fit = None
    if scene.voxgi.quality != "ACCURATE":  # the cones need this update's voxel cascades
        t0 = time.perf_counter()
        caches, settings, anchor, fit = gi_inputs(context, snapshot, scene)
        fit_seconds = time.perf_counter() - t0
        # the last update's state: what did not move is reused (voxgi_addon/gi/update.py)
        state = update_gi(snapshot, caches, settings, anchor=anchor, previous=session.gi_state)
        state.view_shares = view_shares(snapshot, state.grids, fit)
        voxels = {"fit + caches": fit_seconds, **state.timings}
    traced, cut = snapshot, (0, 0, width, height)
    if region is not None:  # the region and its margin, the whole frame's lattice kept
        cut = traced_rect(region, width, height, gi_stride(scene.voxgi, width, height))
        traced = replace(snapshot, camera=crop_camera(snapshot.camera, cut, width, height))
    passes, render_timings, lines = trace_passes(scene, traced, state, cut[2], cut[3],
                                                 frame=(width, height))
    # what the snapshot could not read or leaves out (once each), before the tracer's lines
    lines = [("WARNING", w) for w in dict.fromkeys(snapshot.warnings)] + lines
    if (indirect_source or scene.voxgi.indirect_source) == "PROBES":
        from .probe_preview import apply_probe_indirect
        seconds, line = apply_probe_indirect(scene, traced, passes, cut[2], cut[3])
        render_timings["probes"] = seconds
        lines.append(line)
    if region is not None:
        passes = region_passes(passes, region, cut)
        lines.append(("INFO", f"VoxGI: the Render Region's {region[2]} × {region[3]} pixels "
                              f"traced ({cut[2]} × {cut[3]} with the filters' margin)"))
    session.gi_timings = {"snapshot": snap_seconds, **voxels, **render_timings,
                          "total": time.perf_counter() - start}
    if state is not None:
        session.gi_state = state
        lines += coverage_lines(state, fit, scene.voxgi.view_ahead)
        lines += [("WARNING", w) for w in (fit.warnings if fit is not None else ())]
    else:
        lines.append(("INFO", "VoxGI: Accurate quality traces the triangles; no voxels needed"))
    lines.append(("INFO", timing_text(session.gi_timings)))
    return passes, lines

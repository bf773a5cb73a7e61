"""``voxgi.update`` and ``voxgi.render_preview``: the per-update GI job and the EXR preview.

update : snapshot (main thread) → cascades, direct light, octree on the worker, reusing the
session's voxel caches (voxelizing first if there are none).
render_preview : update, then render the scene camera's passes (Cycles' names and meanings)
into one multilayer OpenEXR file; prints per-stage timings. Runs to completion (it is a render).
Both the operator and the VoxGI render engine (``render/engine.py``) go through
``render_scene_passes``, which traces on the GPU when it can and says so when it cannot.
"""
from __future__ import annotations

import os
import time

import bpy

from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.exr import write_exr
from ..voxgi_addon.gi_update import update_gi
from ..voxgi_addon.mesh_caches import build_scene_caches
from ..voxgi_addon.preview import render_passes
from ..render import gpu_context
from ..ui.properties import cone_settings, gi_settings
from . import engine_jobs
from .scene_poll import VoxGISceneOperator
from .session import scene_session
from .voxelize import snapshot_or_error


def _caches_for(context, snapshot, scene=None):
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


def timing_text(timings: dict[str, float]) -> str:
    return ", ".join(f"{name} {seconds * 1000:.1f} ms" for name, seconds in timings.items())


def octree_text(octree) -> str:
    """Node count and MB per octree level, e.g. 'L6 dense 13,184 nodes 17.3 MB'."""
    return "; ".join(f"L{s.level} {s.kind} {s.nodes:,} nodes {s.bytes / 2**20:.2f} MB"
                     for s in octree.stats())


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
                from ..render.gpu_preview import render_passes_gpu
                from ..render.gpu_volume import GPUVolume
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


def render_scene_passes(context, scene, depsgraph, width, height):
    """Snapshot, update and trace ``scene``'s camera view: (passes, report lines).
    Raises VoxGIError for scenes that cannot be rendered."""
    if scene.camera is None:
        raise VoxGIError("the scene has no camera to render the preview from")
    start = time.perf_counter()
    snapshot, snap_seconds = snapshot_or_error(context, depsgraph)
    caches = _caches_for(context, snapshot, scene)
    state = update_gi(snapshot, caches, gi_settings(scene.voxgi))
    passes, render_timings, lines = trace_passes(scene, snapshot, state, width, height)
    session = scene_session(scene.name_full)
    session.gi_state = state
    session.gi_timings = {"snapshot": snap_seconds, **state.timings, **render_timings,
                          "total": time.perf_counter() - start}
    lines.append(("INFO", timing_text(session.gi_timings)))
    return passes, lines


class VOXGI_OT_update(VoxGISceneOperator, bpy.types.Operator):
    """Transform the voxel caches into camera-anchored cascades, inject direct light and rebuild the octree for the current frame"""

    bl_idname = "voxgi.update"
    bl_label = "Update GI"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene_name = context.scene.name_full
        try:
            snapshot, snap_seconds = snapshot_or_error(context)
            caches = _caches_for(context, snapshot)
        except VoxGIError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        settings = gi_settings(context.scene.voxgi)

        def job(cancel):  # worker thread: engine code only
            return update_gi(snapshot, caches, settings, cancel=cancel)

        def done(state):
            session = scene_session(scene_name)
            session.gi_state = state
            session.gi_timings = {"snapshot": snap_seconds, **state.timings}
            counts = ", ".join(f"{n:,}" for n in state.voxel_counts)
            session.last_report = [("INFO", f"GI updated: cascade voxels {counts}"),
                                   ("INFO", f"octree: {octree_text(state.octree)}"),
                                   ("INFO", timing_text(session.gi_timings)),
                                   *[("WARNING", w) for w in state.warnings]]

        def failed(error):
            scene_session(scene_name).last_report = [("ERROR", str(error))]

        submitted = engine_jobs.submit(scene_name, job, label="Updating GI", on_done=done,
                                       on_error=failed)
        if submitted.state == "running":
            self.report({"INFO"}, "Updating GI in the background…")
            return {"FINISHED"}
        for level, message in scene_session(scene_name).last_report:
            self.report({level}, message)
        return {"FINISHED"} if submitted.state == "done" else {"CANCELLED"}


class VOXGI_OT_render_preview(VoxGISceneOperator, bpy.types.Operator):
    """Render the GI preview of the scene camera to a multilayer OpenEXR file with Cycles-named passes"""

    bl_idname = "voxgi.render_preview"
    bl_label = "Render GI Preview"
    bl_options = {"REGISTER"}

    filepath: bpy.props.StringProperty(name="File Path", description="Output .exr file",
                                       subtype="FILE_PATH", default="//voxgi_preview.exr")
    resolution_x: bpy.props.IntProperty(name="Width", description="Image width in pixels; "
                                        "0 = the scene's", default=0, min=0, max=8192)
    resolution_y: bpy.props.IntProperty(name="Height", description="Image height in pixels; "
                                        "0 = the scene's", default=0, min=0, max=8192)

    def execute(self, context):
        scene = context.scene
        render = scene.render
        width = self.resolution_x or render.resolution_x * render.resolution_percentage // 100
        height = self.resolution_y or render.resolution_y * render.resolution_percentage // 100
        path = bpy.path.abspath(self.filepath)
        try:
            passes, lines = render_scene_passes(context, scene, None, width, height)
            os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
            write_exr(path, passes)
        except (VoxGIError, OSError) as error:
            self.report({"ERROR"}, f"GI preview failed: {error}")
            return {"CANCELLED"}
        session = scene_session(scene.name_full)
        message = f"GI preview {width}×{height} written to {path}"
        session.last_report = [("INFO", message), *lines]
        for level, line in session.last_report:
            print(f"VoxGI: {line}" if not line.startswith("VoxGI") else line)
            self.report({level}, line)
        return {"FINISHED"}


classes = (VOXGI_OT_update, VOXGI_OT_render_preview)

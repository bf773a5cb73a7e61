"""``voxgi.bake_probes``: place, validate, mask and bake the scene's light probes
(docs/probes.md).

Like ``voxgi.voxelize``: the scene is read on the main thread (snapshot, Light Probe Volume
boxes, settings), the engine's ``bake_probe_grid`` runs on the worker thread with progress and
cancel (``voxgi.cancel_job``), and the grids are kept on the main thread (session + a Text
datablock saved with the .blend, ``blender/probe_store.py``). With "Bake With: Voxel Octree
(GPU)" the radiance comes from the last GI update's octree on the GPU, which must run on the
main thread: that bake is synchronous.
"""
from __future__ import annotations

import time
import traceback

import bpy

from ..blender import jobs as engine_jobs
from ..blender import probe_store
from ..blender.operator_poll import VoxGISceneOperator
from ..blender.session import scene_session
from ..blender.settings import probe_settings
from ..blender.snapshot import snapshot_or_error
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.probes.bake import bake_probe_grid
from ..voxgi_addon.probes.grid import memory_report

JOB_LABEL = "Baking probes"
CANCELLED_MESSAGE = "Probe bake cancelled; previous probes kept"


def bake_requests(scene, settings):
    """[(name, box or None, ProbeSettings)]: one per Light Probe Volume object (AUTO), else one
    over the scene's bounds."""
    boxes = probe_store.probe_volume_boxes(scene) if settings.probe_placement == "AUTO" else []
    if not boxes:
        return [("Scene", None, probe_settings(settings))]
    return [(name, (lo, hi), probe_settings(settings, dims)) for name, lo, hi, dims in boxes]


def result_lines(results, seconds) -> list[tuple[str, str]]:
    lines = []
    for r in results:
        g, mem = r.grid, memory_report(r.grid)
        lines.append(("INFO", f"{g.name}: {len(g.volume_cells)} active volumes of "
                              f"{'×'.join(str(int(d)) for d in g.dims)}, {len(g.positions)} probes "
                              f"({r.relocated} relocated, {r.disabled} disabled)"))
        lines.append(("INFO", f"{g.name}: memory {mem['total'] / 1024:.1f} KiB (SH index "
                              f"{mem['sh_index']} B, SH {mem['sh_coefficients']} B, occlusion "
                              f"index {mem['occlusion_index']} B, masks {mem['occlusion_masks']} B)"))
    lines.append(("INFO", f"Probes baked in {seconds:.2f} s"))
    return lines


class VOXGI_OT_bake_probes(VoxGISceneOperator, bpy.types.Operator):
    """Place light probes where there is geometry, find their occlusion masks and bake their incoming light"""

    bl_idname = "voxgi.bake_probes"
    bl_label = "Bake Probes"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene = context.scene
        scene_name = scene.name_full
        settings = scene.voxgi
        try:
            snapshot, _ = snapshot_or_error(context)
            requests = bake_requests(scene, settings)
            if settings.probe_bake_method == "VOXELS_GPU":
                return self._bake_on_gpu(context, snapshot, requests)
        except VoxGIError as error:
            engine_jobs.cancel(scene_name, discard=True)
            _apply_error(scene_name, error)
            return self._finish(scene_session(scene_name).last_report, {"CANCELLED"})

        def job(cancel):  # worker thread: engine code only
            start = time.perf_counter()
            results = []
            for i, (name, box, bake) in enumerate(requests):
                def progress(share, i=i):
                    probe_store.set_progress(scene_name, (i + share) / len(requests))
                results.append(bake_probe_grid(snapshot, bake, box, cancel=cancel,
                                               progress=progress, name=name))
            probe_store.set_progress(scene_name, None)
            return results, time.perf_counter() - start

        submitted = engine_jobs.submit(
            scene_name, job, label=JOB_LABEL,
            on_done=lambda result: _apply_result(scene_name, *result),
            on_cancel=lambda: _apply_cancel(scene_name),
            on_error=lambda error: _apply_error(scene_name, error))
        if submitted.state == "running":
            self.report({"INFO"}, f"Baking {len(requests)} probe grid(s) in the background…")
            return {"FINISHED"}
        status = {"FINISHED"} if submitted.state == "done" else {"CANCELLED"}
        return self._finish(scene_session(scene_name).last_report, status)

    def _bake_on_gpu(self, context, snapshot, requests):
        from ..render.gpu_probes import bake_grid_from_octree

        scene = context.scene
        start = time.perf_counter()
        results = [bake_grid_from_octree(context, scene, snapshot, bake, box, name)
                   for name, box, bake in requests]
        _apply_result(scene.name_full, results, time.perf_counter() - start)
        return self._finish(scene_session(scene.name_full).last_report, {"FINISHED"})

    def _finish(self, lines, status):
        for level, message in lines:
            self.report({level}, message)
        return status


def _apply_result(scene_name, results, seconds) -> None:
    scene = bpy.data.scenes.get(scene_name)
    if scene is None:
        return
    probe_store.save_grids(scene, [r.grid for r in results])
    scene_session(scene_name).last_report = result_lines(results, seconds)
    engine_jobs.tag_sidebars()
    for window in bpy.context.window_manager.windows if bpy.context.window_manager else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def _apply_cancel(scene_name) -> None:
    probe_store.set_progress(scene_name, None)
    scene_session(scene_name).last_report = [("INFO", CANCELLED_MESSAGE)]


def _apply_error(scene_name, error) -> None:
    probe_store.set_progress(scene_name, None)
    session = scene_session(scene_name)
    if isinstance(error, VoxGIError):
        session.last_report = [("ERROR", f"Probe bake failed: {error}")]
    else:
        traceback.print_exception(error)
        session.last_report = [("ERROR", f"Probe bake failed: {type(error).__name__}: {error} "
                                         "(see the system console)")]


classes = (VOXGI_OT_bake_probes,)

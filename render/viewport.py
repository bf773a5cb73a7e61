"""The VoxGI engine in the 3D view's Rendered mode: ``view_update`` and ``view_draw``.

``view_update`` hands the depsgraph's updates to the scene's ``LiveGI``
(``blender/viewport_session.py``), which plans them and runs the CPU stages on the worker.
``view_draw`` runs on every redraw and calls ``draw_view``:

1. the view's camera from ``RegionView3D.view_matrix`` / ``window_matrix`` at
   ``Scene.voxgi_viewport.resolution_fraction`` of the region's size
   (``voxgi_addon/scene/view_camera.py``: perspective or orthographic, camera or free view);
   a new view is reported to ``LiveGI.view_changed`` (trace again; the cascades move when the
   view leaves their anchor cell);
2. when the applied results, the view, the pass or the trace settings changed since the last
   trace: in Fast quality upload the octree atlas the worker laid out
   (``GPUVolume.update(…, atlas=…)``); trace with the GPU tracer
   (``gpu_preview.render_passes_gpu``, as F12), keeping the chosen pass as a texture;
3. draw that texture over the region. While newer work runs, the last texture is drawn again:
   the view never goes blank.

GPU objects (textures, the atlas) belong to one ``ViewportRenderer`` per engine instance and
are freed with it, on unregister and at exit (``release``; docs/gi_pipeline.md "GPU resources
at exit").
"""
from __future__ import annotations

import dataclasses
import time
import weakref

import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..blender.settings import cone_settings, trace_options
from ..blender.viewport_session import live_gi
from ..blender.viewport_settings import VIEWPORT_PASSES
from ..voxgi_addon.scene.view_camera import camera_from_view
from .gpu_volume import GPUVolume

_renderers: "weakref.WeakSet[ViewportRenderer]" = weakref.WeakSet()


def viewport_size(region_width: int, region_height: int, fraction: float) -> tuple[int, int]:
    """Pixels traced for a region of that size at ``fraction`` of it (at least 1 × 1)."""
    return (max(1, round(region_width * fraction)), max(1, round(region_height * fraction)))


def _matrix(m) -> np.ndarray:
    return np.array(m, dtype=np.float64).reshape(4, 4)


class ViewportRenderer:
    """The traced image of one 3D view and the GPU objects behind it."""

    def __init__(self):
        self.volume = GPUVolume()
        self.texture = None        # RGBA32F, the shown pass; kept until a newer trace replaces it
        self.trace_key = None      # what ``texture`` shows (see ``_trace_key``)
        self.view_key = None       # the last view seen
        self.timings: dict[str, float] = {}
        self.traces = 0            # how many times this view traced (tests, panel)
        self.error = ""
        _renderers.add(self)

    def free(self) -> None:
        self.texture = self.trace_key = None
        self.volume = GPUVolume()

    # ------------------------------------------------------------------ tracing

    def _trace_key(self, live, camera_key, scene, pass_name):
        s = scene.voxgi
        return (live.generation, camera_key, pass_name, cone_settings(s), s.light_samples,
                s.shadows, s.gi_resolution, s.tracer, s.quality, s.gi_rays, s.glossy_indirect,
                s.seed)

    def trace(self, live, scene, camera, camera_key, pass_name: str) -> bool:
        """Trace ``live``'s applied results seen by ``camera`` unless the texture already
        shows them; True when it traced."""
        if live.staged is None or live.snapshot is None:
            return False
        key = self._trace_key(live, camera_key, scene, pass_name)
        if key == self.trace_key and self.texture is not None:
            return False
        from .gpu_preview import render_passes_gpu

        settings = scene.voxgi
        cones = cone_settings(settings)
        width, height = camera.resolution
        t0 = time.perf_counter()
        if settings.quality != "ACCURATE":  # Accurate traces the triangles, not the octree
            self.volume.update(live.staged.state.octree, cones, atlas=live.atlas)
        upload = time.perf_counter() - t0
        snapshot = dataclasses.replace(live.snapshot, camera=camera)
        # point-sampled: one camera pass, not F12's anti-aliased sub-pixel passes (which cost
        # 2.3x; progressive viewport accumulation, issue 19, is where they belong)
        options = {**trace_options(settings, width, height), "filter_width": 0.0}
        passes, timings = render_passes_gpu(snapshot, live.staged.state, width, height, cones,
                                            volume=self.volume, **options)
        image = np.asarray(passes[pass_name], np.float32)
        rgba = np.concatenate([image, np.ones(image.shape[:2] + (1,), np.float32)], axis=2)
        flat = np.ascontiguousarray(np.flipud(rgba)).ravel()  # GPU rows go bottom to top
        self.texture = gpu.types.GPUTexture((width, height), format="RGBA32F",
                                            data=gpu.types.Buffer("FLOAT", flat.size, flat))
        self.trace_key = key
        self.traces += 1
        self.timings = {"atlas upload": upload, **timings, "trace": time.perf_counter() - t0}
        return True

    # ------------------------------------------------------------------ drawing

    def draw(self) -> bool:
        """Draw the last traced texture over the whole viewport (NDC quad); False if none."""
        if self.texture is None:
            return False
        from mathutils import Matrix

        shader = gpu.shader.from_builtin("IMAGE")
        corners = ((-1, -1), (1, -1), (-1, 1), (1, 1))
        batch = batch_for_shader(shader, "TRI_STRIP", {"pos": corners,
                                                       "texCoord": ((0, 0), (1, 0), (0, 1), (1, 1))})
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix.Identity(4))
            shader.bind()
            shader.uniform_sampler("image", self.texture)
            batch.draw(shader)
        return True


def draw_view(renderer: ViewportRenderer, scene, depsgraph, view_matrix, window_matrix,
              region_width: int, region_height: int, bind=None, unbind=None) -> bool:
    """What ``view_draw`` does (module doc, steps 1–3) for a region of that size; tests call
    it with a camera's matrices into a ``GPUOffScreen``. bind / unbind : called around the
    texture draw (the engine's display-space shader). Returns whether anything was drawn."""
    view_settings = scene.voxgi_viewport
    width, height = viewport_size(region_width, region_height, view_settings.resolution_fraction)
    view, window = _matrix(view_matrix), _matrix(window_matrix)
    camera = camera_from_view(view, window, width, height)
    camera_key = (view.tobytes(), window.tobytes(), width, height)
    live = live_gi(scene.name_full)
    if camera_key != renderer.view_key:
        renderer.view_key = camera_key
        live.view_changed(camera, scene, depsgraph)
    try:
        renderer.trace(live, scene, camera, camera_key, VIEWPORT_PASSES[view_settings.viewport_pass])
        renderer.error = ""
    except Exception as error:  # noqa: BLE001 - keep drawing the last image, say why
        renderer.error = f"viewport trace failed: {type(error).__name__}: {error}"
        live.error = renderer.error
    if bind is not None:
        bind()
    try:
        return renderer.draw()
    finally:
        if unbind is not None:
            unbind()


def view_update(engine, context, depsgraph) -> None:
    """``RenderEngine.view_update``: plan and schedule the depsgraph's updates."""
    scene = depsgraph.scene_eval.original
    live = live_gi(scene.name_full)
    region_data = getattr(context, "region_data", None)
    region = getattr(context, "region", None)
    if live.view_camera is None and region_data is not None and region is not None:
        fraction = scene.voxgi_viewport.resolution_fraction
        width, height = viewport_size(region.width, region.height, fraction)
        live.view_camera = camera_from_view(_matrix(region_data.view_matrix),
                                            _matrix(region_data.window_matrix), width, height)
    live.update(scene, depsgraph)


def view_draw(engine, context, depsgraph) -> None:
    """``RenderEngine.view_draw``: trace when needed and draw (``draw_view``)."""
    renderer = getattr(engine, "voxgi_viewport", None)
    if renderer is None:
        renderer = engine.voxgi_viewport = ViewportRenderer()
    scene = depsgraph.scene_eval.original
    region, region_data = context.region, context.region_data
    gpu.state.blend_set("ALPHA_PREMULT")
    try:
        draw_view(renderer, scene, depsgraph, region_data.view_matrix, region_data.window_matrix,
                  region.width, region.height, bind=lambda: engine.bind_display_space_shader(scene),
                  unbind=engine.unbind_display_space_shader)
    finally:
        gpu.state.blend_set("NONE")


def release() -> None:
    """Free every viewport's textures and atlas (unregister, exit)."""
    for renderer in list(_renderers):
        renderer.free()

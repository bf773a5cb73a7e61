"""The VoxGI engine in the 3D view's Rendered mode: ``view_update`` and ``view_draw``.

``view_update`` hands the depsgraph's updates to the scene's ``LiveGI``
(``blender/viewport_session.py``), which plans them and runs the CPU stages on the worker.
``view_draw`` runs on every redraw and calls ``draw_view``:

1. the view's camera from ``RegionView3D.view_matrix`` / ``window_matrix`` at
   ``Scene.voxgi_viewport.resolution_fraction`` of the region's size
   (``voxgi_addon/scene/view_camera.py``: perspective or orthographic, camera or free view);
   a new view is reported to ``LiveGI.view_changed`` (trace again; the cascades move when the
   view leaves their anchor cell);
2. the image is keyed by everything it depends on (``trace_key``): the applied results'
   generation (bumped by every depsgraph change the session acted on), the view and
   projection matrices, the traced size (region size × fraction), the pass, the cone
   settings and every tracer option (``trace_options``). When the shown texture has that key,
   nothing is traced: the redraw is one textured quad ("Cached"). Otherwise, in Fast quality
   upload the octree atlas the worker laid out (``GPUVolume.update(…, atlas=…)``) and trace
   with the GPU tracer (``gpu_preview.render_passes_gpu``, as F12), keeping the chosen pass
   as a texture. With *Coarse First Image* (default on) a new key is first traced at half
   the width and height (a quarter of the pixels, "Coarse") and a redraw is requested, so
   the next ``view_draw`` traces the full image — while orbiting every draw is coarse, and
   the full image follows when the view stops;
3. draw that texture over the region. While newer work runs, the last texture is drawn again:
   the view never goes blank.
4. the status line (``ViewportRenderer.status``: stage, time, quality) goes to the view's
   header through ``RenderEngine.update_stats`` and to the sidebar (``LiveGI.view_status``).

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

from ..blender.settings import cone_settings, gi_stride, trace_options
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


def _options(settings, width: int, height: int, full=None) -> dict:
    """The tracer's options for a ``width`` × ``height`` viewport image: F12's, but
    point-sampled (one camera pass, not F12's anti-aliased sub-pixel passes, which cost 2.3x;
    progressive viewport accumulation, issue 19, is where they belong). full : the full
    image's size when this is its coarse first image: the GI stride is the full image's, so
    the coarse image traces a quarter of the gather points too (GI Resolution Auto would
    otherwise trace as many as for the full image)."""
    options = {**trace_options(settings, width, height), "filter_width": 0.0}
    if full is not None:
        options["gi_stride"] = gi_stride(settings, *full)
    return options


def coarse_size(width: int, height: int) -> tuple[int, int]:
    """The coarse first image's size: half the width and height, a quarter of the pixels."""
    return max(1, (width + 1) // 2), max(1, (height + 1) // 2)


class ViewportRenderer:
    """The traced image of one 3D view and the GPU objects behind it."""

    def __init__(self):
        self.volume = GPUVolume()
        self.texture = None        # RGBA32F, the shown pass; kept until a newer trace replaces it
        self.trace_key_shown = None  # what ``texture`` shows (``trace_key``)
        self.view_key = None       # the last view seen
        self.timings: dict[str, float] = {}
        self.traces = 0            # how many times this view traced (tests, panel)
        self.shown = ""            # what the last draw showed: "Coarse", "Traced", "Cached", ""
        self.coarse = False        # the texture is a coarse (quarter-pixel) image
        self.trace_seconds = 0.0   # how long the shown texture took to trace
        self.status = ""           # the status line (header, sidebar)
        self.error = ""
        _renderers.add(self)

    def free(self) -> None:
        self.texture = self.trace_key_shown = None
        self.volume = GPUVolume()

    # ------------------------------------------------------------------ tracing

    @staticmethod
    def trace_key(live, camera_key, scene, pass_name, options) -> tuple:
        """Everything the traced image depends on: the applied results, the view (view and
        projection matrices, traced size), the pass, the cones and every tracer option."""
        s = scene.voxgi
        return (live.generation, camera_key, pass_name, cone_settings(s), s.tracer, s.quality,
                tuple(sorted(options.items())))

    def shows(self, live, scene, camera_key, pass_name: str, full=None) -> bool:
        """Whether the texture is the image of ``camera_key`` (matrices, width, height) for
        the current results and settings: a redraw then only draws it."""
        if self.texture is None or live.staged is None:
            return False
        width, height = camera_key[2], camera_key[3]
        options = _options(scene.voxgi, width, height, full)
        return self.trace_key(live, camera_key, scene, pass_name, options) == self.trace_key_shown

    def trace(self, live, scene, camera, camera_key, pass_name: str, full=None) -> bool:
        """Trace ``live``'s applied results seen by ``camera`` unless the texture already
        shows them; True when it traced. full : the full image's (width, height) when this
        trace is its coarse first image (``_options``)."""
        if live.staged is None or live.snapshot is None:
            return False
        settings = scene.voxgi
        width, height = camera.resolution
        options = _options(settings, width, height, full)
        key = self.trace_key(live, camera_key, scene, pass_name, options)
        if key == self.trace_key_shown and self.texture is not None:
            return False
        from .gpu_preview import render_passes_gpu

        cones = cone_settings(settings)
        t0 = time.perf_counter()
        if settings.quality != "ACCURATE":  # Accurate traces the triangles, not the octree
            self.volume.update(live.staged.state.octree, cones, atlas=live.atlas)
        upload = time.perf_counter() - t0
        snapshot = dataclasses.replace(live.snapshot, camera=camera)
        passes, timings = render_passes_gpu(snapshot, live.staged.state, width, height, cones,
                                            volume=self.volume, **options)
        image = np.asarray(passes[pass_name], np.float32)
        rgba = np.concatenate([image, np.ones(image.shape[:2] + (1,), np.float32)], axis=2)
        flat = np.ascontiguousarray(np.flipud(rgba)).ravel()  # GPU rows go bottom to top
        self.texture = gpu.types.GPUTexture((width, height), format="RGBA32F",
                                            data=gpu.types.Buffer("FLOAT", flat.size, flat))
        self.trace_key_shown = key
        self.traces += 1
        self.coarse = full is not None
        self.trace_seconds = time.perf_counter() - t0
        self.timings = {"atlas upload": upload, **timings, "trace": self.trace_seconds}
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
              region_width: int, region_height: int, bind=None, unbind=None,
              redraw=None) -> bool:
    """What ``view_draw`` does (module doc, steps 1–4) for a region of that size; tests call
    it with a camera's matrices into a ``GPUOffScreen``. bind / unbind : called around the
    texture draw (the engine's display-space shader); redraw : asks for another draw (the
    engine's ``tag_redraw``) after a coarse first image. Returns whether anything was drawn."""
    view_settings = scene.voxgi_viewport
    width, height = viewport_size(region_width, region_height, view_settings.resolution_fraction)
    view, window = _matrix(view_matrix), _matrix(window_matrix)
    camera_key = (view.tobytes(), window.tobytes(), width, height)
    pass_name = VIEWPORT_PASSES[view_settings.viewport_pass]
    live = live_gi(scene.name_full)
    if camera_key != renderer.view_key:
        renderer.view_key = camera_key
        live.view_changed(camera_from_view(view, window, width, height), scene, depsgraph)
    traced = ""
    blend = gpu.state.blend_get()
    # The trace rasterizes its G-buffer: with the caller's blending on (view_draw's state)
    # its triangles blended into the cleared targets and the image was 3% off F12's.
    gpu.state.blend_set("NONE")
    if not renderer.shows(live, scene, camera_key, pass_name):
        small = coarse_size(width, height)
        small_key = (camera_key[0], camera_key[1], *small)
        coarse = (view_settings.coarse_first and small != (width, height)
                  and not (renderer.coarse
                           and renderer.shows(live, scene, small_key, pass_name, (width, height))))
        size, key = (small, small_key) if coarse else ((width, height), camera_key)
        try:
            if renderer.trace(live, scene, camera_from_view(view, window, *size), key, pass_name,
                              full=(width, height) if coarse else None):
                traced = "Coarse" if coarse else "Traced"
                if coarse and redraw is not None:
                    redraw()  # the full image on the next draw
            renderer.error = ""
        except Exception as error:  # noqa: BLE001 - keep drawing the last image, say why
            renderer.error = f"viewport trace failed: {type(error).__name__}: {error}"
            live.error = renderer.error
    gpu.state.blend_set(blend)
    if traced:
        renderer.shown = traced
    elif renderer.texture is None:
        renderer.shown = ""
    elif renderer.shows(live, scene, camera_key, pass_name):
        renderer.shown = "Cached"
    else:  # a failed trace, or a coarse image of this view kept: the last image stays
        renderer.shown = "Coarse" if renderer.coarse else "Previous"
    renderer.status = status_line(renderer, scene, live)
    live.view_status, live.view_shown = renderer.status, renderer.shown
    if bind is not None:
        bind()
    try:
        return renderer.draw()
    finally:
        if unbind is not None:
            unbind()


QUALITY_NAMES = {"ACCURATE": "Accurate", "FAST": "Fast"}


def status_line(renderer: ViewportRenderer, scene, live) -> str:
    """The view's status: 'VoxGI | Sample 1/1 | Traced in 0.74 s | Accurate', '… | Cached
    (converged) …', 'VoxGI | Coarse (¼ of the pixels) in 0.20 s | … | refining'; a running
    job or an error is added."""
    quality = QUALITY_NAMES.get(scene.voxgi.quality, scene.voxgi.quality.title())
    if renderer.error:
        return f"VoxGI | {renderer.error}"
    seconds = f"{renderer.trace_seconds:.2f} s"
    shown = renderer.shown
    if shown == "":
        line = "VoxGI | Waiting for the first GI update"
    elif shown == "Coarse":
        line = f"VoxGI | Sample 0/1 | Coarse (¼ of the pixels) in {seconds} | {quality} | refining"
    elif shown == "Traced":
        line = f"VoxGI | Sample 1/1 | Traced in {seconds} | {quality}"
    elif shown == "Cached":
        line = f"VoxGI | Sample 1/1 | Cached, traced in {seconds} | {quality}"
    else:
        line = f"VoxGI | Previous image | {quality}"
    if live.running is not None:
        line += " | Updating GI…"
    elif shown == "Cached":
        line = line.replace("Cached,", "Cached (converged),")
    return line


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

    def bind():  # blending for the texture draw only, never for the trace (draw_view)
        gpu.state.blend_set("ALPHA_PREMULT")
        engine.bind_display_space_shader(scene)

    def unbind():
        engine.unbind_display_space_shader()
        gpu.state.blend_set("NONE")

    draw_view(renderer, scene, depsgraph, region_data.view_matrix, region_data.window_matrix,
              region.width, region.height, bind=bind, unbind=unbind, redraw=engine.tag_redraw)
    engine.update_stats("", renderer.status)  # the view's header shows it


def release() -> None:
    """Free every viewport's textures and atlas (unregister, exit)."""
    for renderer in list(_renderers):
        renderer.free()

"""The VoxGI engine in the 3D view's Rendered mode: ``view_update`` and ``view_draw``.

``view_update`` hands the depsgraph's updates to the scene's ``LiveGI``
(``blender/viewport_session.py``), which plans them and runs the CPU stages on the worker; a
new snapshot's GPU scene is prepared at once on the view's own thread (``viewport_prepare``).
``view_draw`` runs on every redraw and calls ``draw_view``:

0. until the view can trace what it shows — the snapshot's GPU scene sent a part per draw,
   the vertex batch a chunk per draw, the kernels compiled one per draw (``viewport_prepare``,
   docs/gi_pipeline.md "Entering Rendered mode") — a draw runs those steps within the budget,
   shows the quick image (entering Rendered mode) or the last image, and asks for a redraw;

1. the view's camera from ``RegionView3D.view_matrix`` / ``window_matrix`` at
   ``Scene.voxgi_viewport.resolution_fraction`` of the region's size
   (``voxgi_addon/scene/view_camera.py``: perspective or orthographic, camera or free view);
   with a Render Region (``render_border``: the view's own, or the scene's inside the camera
   frame in the camera view, as Cycles' view takes them) only the region's pixels are traced
   and drawn (``view_frame``);
   a new view is reported to ``LiveGI.view_changed`` (trace again; the cascades move when the
   view leaves their anchor cell);
2. the image is keyed by everything it depends on (``trace_key``): what it traces
   (``LiveGI.image_source``: in Accurate the latest snapshot, taken on the main thread right
   after a change, so the view does not wait for the worker's voxels; in Fast the applied
   results' generation, bumped by every depsgraph change the session acted on), the view and
   projection matrices, the traced size (region size × fraction), the pass, the cone
   settings, every tracer option (``trace_options``), the Viewport Samples and the pixel
   filter. A new key restarts the progressive accumulation (``progressive.py``); in Fast
   quality the octree atlas the worker laid out is uploaded first (``GPUVolume.update(…,
   atlas=…)``). Each draw then traces **one slice** — the coarse image of the whole view
   first (*Coarse First Image*), then one tile of one sample — with F12's tracer
   (``gpu_preview.render_passes_gpu``), adds it to the samples and asks for a redraw until
   the Viewport Samples are in ("Coarse", "Refining", "Converged"); a converged key traces
   nothing ("Cached");
3. draw the current estimate's texture over the region. While newer work runs, the last
   texture is drawn again: the view never goes blank.
4. the status line (``status_line``: "Sample N/M", elapsed time, stage, quality) goes to the
   view's header through ``RenderEngine.update_stats`` and to the sidebar
   (``LiveGI.view_status``, ``view_samples``).

GPU objects (textures, the atlas) belong to one ``ViewportRenderer`` per engine instance and
are freed with it, on unregister and at exit (``release``; docs/gi_pipeline.md "GPU resources
at exit").
"""
from __future__ import annotations

import time
import weakref

import bpy
import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..blender.settings import cone_settings, gi_stride, pixel_filter_width
from ..blender.viewport_session import READ_SLICE, SNAPSHOT_HOOKS, live_gi
from ..blender.viewport_settings import VIEWPORT_PASSES
from ..voxgi_addon.scene.view_camera import border_rect, camera_from_view, crop_window
from . import viewport_prepare
from .frame import running as running_stage
from .gpu_fast import cone_volumes
from .gpu_gather import CHUNK_GROWTH
from .gpu_scene import current_scene
from .gpu_shaders import counters, note_upload
from .gpu_volume import GPUVolume
from .progressive import SLICE_BUDGET, ProgressiveImage, base_options, tracer
from .viewport_bounces import FastCacheSource, ViewportBounces
from .viewport_cache import ViewportCache
from .viewport_prepare import ViewPreparation
from .viewport_world import WorldView

_renderers: "weakref.WeakSet[ViewportRenderer]" = weakref.WeakSet()
# the process's first LAPACK call (9–28 ms: OpenBLAS starting) made with the module, at the
# add-on's registration (render/engine.py imports it), not in a view_update or a draw
np.linalg.inv(np.eye(4))


def viewport_size(region_width: int, region_height: int, fraction: float) -> tuple[int, int]:
    """Pixels traced for a region of that size at ``fraction`` of it (at least 1 × 1)."""
    return (max(1, round(region_width * fraction)), max(1, round(region_height * fraction)))


WHOLE = ((-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0))  # the region's corners in NDC


def view_frame(window, region_width: int, region_height: int, fraction: float, border=None):
    """(window matrix, width, height, corners) of what a view traces and where it draws it:
    the region at ``fraction`` of its size, or with a Render Region ``border`` (x0, y0, x1, y1,
    fractions of the region from its bottom left) only the region's pixels, cut as F12 cuts
    them (``border_rect``), their window cropped to them and their corners in the region's
    NDC. width and height are 0 when the border lies outside the region."""
    width, height = viewport_size(region_width, region_height, fraction)
    if border is None:
        return window, width, height, WHOLE
    rect = border_rect(border, width, height)
    x0, y0, w, h = rect
    if w < 1 or h < 1:
        return window, 0, 0, WHOLE
    corners = tuple((-1.0 + 2.0 * x / width, -1.0 + 2.0 * y / height)
                    for y in (y0, y0 + h) for x in (x0, x0 + w))
    return crop_window(window, rect, width, height), w, h, corners


def render_border(context, scene, depsgraph=None):
    """The Render Region Cycles' Rendered view traces, as fractions (x0, y0, x1, y1) of the
    region from its bottom left, or None: in the camera view the scene's (Output › Format ›
    Render Region, Ctrl B there) placed in the camera's frame; elsewhere the view's own
    (View › Render Region, Ctrl B outside the camera view)."""
    region_data = getattr(context, "region_data", None)
    if getattr(region_data, "view_perspective", None) == "CAMERA":
        render = scene.render
        if not render.use_border or scene.camera is None:
            return None
        camera = scene.camera if depsgraph is None else scene.camera.evaluated_get(depsgraph)
        to_ndc = _matrix(region_data.window_matrix) @ _matrix(region_data.view_matrix) \
            @ _matrix(camera.matrix_world)
        corners = np.array([[*c, 1.0] for c in camera.data.view_frame(scene=scene)]) @ to_ndc.T
        ndc = corners[:, :2] / corners[:, 3:4]
        (fx0, fy0), (fx1, fy1) = (ndc.min(0) + 1.0) / 2.0, (ndc.max(0) + 1.0) / 2.0
        return (fx0 + render.border_min_x * (fx1 - fx0), fy0 + render.border_min_y * (fy1 - fy0),
                fx0 + render.border_max_x * (fx1 - fx0), fy0 + render.border_max_y * (fy1 - fy0))
    space = getattr(context, "space_data", None)
    if not getattr(space, "use_render_border", False):
        return None
    return (space.render_border_min_x, space.render_border_min_y,
            space.render_border_max_x, space.render_border_max_y)


def _matrix(m) -> np.ndarray:
    return np.array(m, dtype=np.float64).reshape(4, 4)


def _options(settings, width: int, height: int, full=None) -> dict:
    """The tracer's options for a one-shot ``width`` × ``height`` viewport image (``trace``):
    F12's, point-sampled. full : the full image's size when this is a reduced image of it: the
    GI stride is the full image's."""
    options = base_options(settings, width, height)
    if full is not None:
        options["gi_stride"] = gi_stride(settings, *full)
    return options


# of a draw's budget: the most work a draw may have done to also build the texture's draw
# code before the view has an image (``ViewportRenderer.draw``)
WARM_DISPLAY_WORK = 0.25


class ViewportRenderer:
    """The image of one 3D view, its progressive accumulation and the GPU objects behind it."""

    def __init__(self, budget: float = SLICE_BUDGET):
        self.volume = GPUVolume()
        self.texture = None        # RGBA32F, the shown estimate; kept until a newer one
        self.corners = WHOLE       # where it is drawn: the region, or its Render Region
        self.frame_corners = WHOLE  # ... and where this draw's frame goes (``view_frame``):
        #                             a texture keeps its own until a new one replaces it
        self.progressive = ProgressiveImage(budget)
        self.view_key = None       # the last view seen
        self.timings: dict[str, float] = {}
        self.traces = 0            # slices (tracer calls) this view traced (tests, panel)
        self.shown_version = None  # the image source's version of what the view shows
        self.shown = ""            # what the last draw showed: "Coarse", "Refining",
        #                            "Converged" (traced this draw), "Cached", "Previous",
        #                            "World" (the world alone: viewport_world), ""
        self.status = ""           # the status line (header, sidebar)
        self.error = ""
        # the G-buffer shader and vertex batch of this view's GPU context, the scene and the
        # kernels made ready a step per draw, the quick image (viewport_prepare)
        self.prepare = ViewPreparation()
        self.quick_key = None      # the view of the quick image shown (None: a GI image)
        self.display_warm = False  # the texture's draw made once (``draw``) before an image
        self.cache = ViewportCache()  # the radiance cache, built a stage at a time
        self.world = WorldView()   # a view layer that shows no mesh: its world alone
        self.bounces = ViewportBounces()  # Fast: the voxels with its bounces, made on the worker
        self.bounced = None        # ... those this key's image reflects (None: one bounce)
        _renderers.add(self)

    def free(self) -> None:
        self.texture = None
        self.progressive = ProgressiveImage(self.progressive.budget)
        self.volume = GPUVolume()
        self.prepare.free()
        self.quick_key = None
        self.cache.free()
        self.world = WorldView()
        self.bounces.free()
        self.bounced = None

    # ------------------------------------------------------------------ tracing

    @staticmethod
    def trace_key(version, camera_key, scene, pass_name, options) -> tuple:
        """Everything the image depends on: what it traces (``LiveGI.image_source``'s
        version), the view (view and projection matrices, traced size), the pass, the cones,
        every tracer option and the sample target, the film (Film › Transparent)."""
        s = scene.voxgi
        return (version, camera_key, pass_name, cone_settings(s), s.tracer, s.quality,
                tuple(sorted(options.items())), scene.voxgi_viewport.samples,
                pixel_filter_width(scene), bool(scene.render.film_transparent))

    def trace(self, live, scene, camera, key, pass_name: str) -> bool:
        """One-shot: trace what ``live`` has for the view (``LiveGI.image_source``) seen by
        ``camera`` whole (its resolution) into the texture, outside the progressive
        accumulation; True when it traced."""
        settings = scene.voxgi
        if live.image_source(settings.quality) is None:
            return False
        width, height = camera.resolution
        if settings.quality != "ACCURATE":
            self.volume.update(live.staged.state.octree, cone_settings(settings),
                               atlas=live.atlas)
        passes = tracer(live, self.volume, settings)(camera, width, height,
                                                      _options(settings, width, height))
        self.upload(np.asarray(passes[pass_name], np.float32))
        self.traces += 1
        return True

    def upload(self, image) -> None:
        """Make ``image`` ((H, W, 3) opaque, or (H, W, 4) RGBA; row 0 on top) the shown
        texture."""
        height, width = image.shape[:2]
        rgba = image if image.shape[2] == 4 else \
            np.concatenate([image, np.ones((height, width, 1), np.float32)], axis=2)
        flat = np.ascontiguousarray(np.flipud(rgba)).ravel()  # GPU rows go bottom to top
        self.show(gpu.types.GPUTexture((width, height), format="RGBA32F",
                                       data=gpu.types.Buffer("FLOAT", flat.size, flat)))

    def show(self, texture) -> None:
        """Make ``texture``, an image of this draw's frame, the one drawn (where the frame
        lies: the region or its Render Region)."""
        self.texture, self.corners = texture, self.frame_corners

    @property
    def raster(self):
        """The G-buffer raster shader of this view's GPU context (``viewport_prepare``)."""
        return self.prepare.raster

    def _prepared(self, live, scene, view, window, started: float) -> str:
        """The steps of this draw toward tracing ``live``'s image source (``viewport_prepare``:
        the scene, the vertex batch and the kernels, a bounded step per draw; the quick image
        meanwhile when the view shows no image yet): "" when the view can trace, else
        "Quick" (the quick image was drawn) or "Preparing"."""
        settings = scene.voxgi
        progressive = self.progressive
        snapshot = live.image_source(settings.quality)[0]
        drew = []
        acc, key = progressive.accumulation, progressive.key
        quick = None
        showing_quick = self.texture is None or self.quick_key is not None
        if showing_quick and self.quick_key != key:
            # the quick image of this key at the first coarse image's size and camera: its
            # G-buffer is that image's (viewport_prepare.QuickView)
            options = base_options(settings, acc.width, acc.height)
            size = progressive.coarse_size(options["gi_stride"])

            def show(texture):
                self.show(texture)
                self.quick_key = key
                self.shown_version = key[0]
                drew.append(1)

            quick = viewport_prepare.QuickView(
                key, size, camera_from_view(view, window, *size), options["filter_width"],
                progressive.film and acc.transparent, show)
        ready = self.prepare.advance(live.scene_name, snapshot, settings, progressive.budget,
                                     started, quick=quick,
                                     whole=progressive.stage_budget is None)
        if ready:
            return ""
        self.timings = {**self.prepare.timings, "view_draw work": time.perf_counter() - started}
        return "Quick" if drew else "Preparing"

    def _cache_chunks(self, chunk, t0: float) -> bool:
        """Run the radiance cache's build in this draw: ``chunk()`` (``ViewportCache.
        advance_any`` or ``advance_first``: whether it ran one), then more while the build
        goes on, the next chunk — taken to last up to CHUNK_GROWTH × the longest so far, as
        the build grows its ray chunks — ends within the slices' stage budget from ``t0``,
        and none compiled a kernel or sent a scene part (a draw does one of each at most).
        A relaxation pass of a small scene's cache is 1–2 ms: one a draw spent most of the
        build's draws on the draws themselves. Whether a chunk ran."""
        mark = counters.compiles, counters.uploads
        started = time.perf_counter()
        if not chunk():
            return False
        budget = self.progressive.stage_budget
        longest = time.perf_counter() - started
        while budget is not None and self.cache.building is not None \
                and (counters.compiles, counters.uploads) == mark \
                and time.perf_counter() - t0 + CHUNK_GROWTH * longest <= budget:
            started = time.perf_counter()
            if not chunk():
                break
            longest = max(longest, time.perf_counter() - started)
        return True

    def refine(self, live, scene, view, window) -> str:
        """One slice of the current key (``ProgressiveImage.step``); what it traced: "Coarse",
        "Refining", "Converged", "Quick" / "Preparing" (the view is being made ready:
        ``viewport_prepare``), or "" (nothing: converged already, or it failed)."""
        settings = scene.voxgi
        progressive = self.progressive
        if progressive.failed:
            return ""
        t0 = time.perf_counter()
        preparing = self._prepared(live, scene, view, window, t0)
        if preparing:
            return preparing
        if progressive.converged:
            if not self.cache.resume():
                return ""
            # converged on the last cache while a new one is built: build on (chunks within
            # the draw's stage budget); its completion changes the image key and the image
            # restarts
            t0 = time.perf_counter()
            self._cache_chunks(self.cache.advance_any, t0)
            self.timings = {"radiance cache stage": time.perf_counter() - t0}
            return "Refining"
        self.cache.image_key = progressive.key  # (what the slices' cache stages ask for)
        if settings.quality == "ACCURATE" and not progressive.coarse_pending \
                and self.cache.building is not None and not self.cache.hold \
                and self._cache_chunks(lambda: self.cache.advance_first(progressive.key), t0):
            # a new radiance cache is being built and its completion restarts Accurate's
            # image: tiles traced before it would be dropped, so its chunks go first, as many
            # a draw as its stage budget holds (docs/gi_pipeline.md "Viewport samples whose
            # gathers end early"; Fast's image waits for the worker's bounced voxels after
            # it, and converges meanwhile)
            self.timings = {"radiance cache stage": time.perf_counter() - t0}
            return "Refining"
        if not progressive.coarse_pending:
            # the tiles' and the radiance cache's kernels, one per draw before they are used
            # (all at once without a budget: the tests' whole slices)
            snapshot = live.image_source(settings.quality)[0]
            whole = progressive.stage_budget is None
            while self.prepare.later_kernels(snapshot, settings, progressive.budget, t0, whole):
                if not whole:
                    self.timings = {**self.prepare.timings,
                                    "view_draw work": time.perf_counter() - t0}
                    return "Refining"
        cache_source = self.cache
        if settings.quality != "ACCURATE":  # Accurate traces the triangles, not the octree
            cones = cone_settings(settings)
            self.volume.update(live.staged.state.octree, cones, atlas=live.atlas)
            if self.volume.uploaded_bytes:
                note_upload("octree atlas")
            cache_source = FastCacheSource(self.cache, self.bounced)
            if self.bounced is not None:  # the worker's bounced octrees: their atlases
                volume, kinds = cone_volumes(self.volume, live.staged.state, self.bounced,
                                             cones, getattr(live.snapshot.world, "radiance",
                                                            None))
                uploaded = sum(v.uploaded_bytes for v in {volume, *kinds.values()})
                if uploaded:
                    note_upload("bounced octree atlases")
                if uploaded and self.texture is not None:  # the upload is this draw's work
                    self.timings = {"atlas upload": time.perf_counter() - t0,
                                    "view_draw work": time.perf_counter() - t0}
                    return "Refining"
        upload = time.perf_counter() - t0
        # the coarse first image reads the last complete radiance cache; a new one's build
        # starts with the tiles (viewport_cache.ViewportCache.hold)
        self.cache.hold = progressive.coarse_pending
        # the slices draw the view's vertex batch of the scene's triangles (viewport_prepare)
        batch = self.prepare.batch_for(current_scene())
        if progressive.coarse_pending and progressive.running is None:
            progressive.coarse_options = self.prepare.first_image_options(
                live.image_source(settings.quality)[0], settings)
            # the quick image's G-buffer is the coarse image's when they agree (its size,
            # camera, triangles and textures): not drawn again
            key, prepare = progressive.key, self.prepare
            progressive.coarse_centre = None if settings.quality != "ACCURATE" else \
                (lambda size: prepare.coarse_centre(key, size, current_scene(), self.raster))
        done = progressive.step(tracer(live, self.volume, settings, staged=True,
                                       raster=self.raster, cache_source=cache_source,
                                       batch=batch),
                                view, window, settings, pixel_filter_width(scene),
                                # the preparation's last steps ran in this draw
                                spent=time.perf_counter() - t0 if self.prepare.timings else 0.0)
        if done is None:
            return ""
        if not done.finished:  # a stage of the slice: the next draw goes on with it
            self.timings = {"atlas upload": upload,
                            f"stage ({running_stage()})": time.perf_counter() - t0 - upload,
                            "view_draw work": time.perf_counter() - t0}
            return "Coarse" if progressive.coarse_pending else (
                "Converged" if progressive.converged else "Refining")
        self.show(progressive.image)  # on the GPU: drawn as it is, nothing read back
        self.shown_version = progressive.key[0]
        self.quick_key = None  # a GI image from now on: no quick image over it
        self.traces += 1
        self.timings = {"atlas upload": upload, f"slice ({done.kind})": done.seconds,
                        "view_draw work": time.perf_counter() - t0}
        if done.kind == "coarse":
            return "Coarse"
        return "Converged" if progressive.converged else "Refining"

    # ------------------------------------------------------------------ drawing

    def draw(self) -> bool:
        """Draw the shown texture over the region, or its Render Region (``corners``, an NDC
        quad); False if none. While there is none, the first call whose draw worked less than
        ``WARM_DISPLAY_WORK`` draws a transparent texel over a corner instead, which changes no
        pixel (premultiplied blending): the draw's code is then built (6–14 ms on llvmpipe) in
        a draw with time to spare, not in the one that shows the first image beside its last
        stages."""
        if self.texture is None:
            work = self.timings.get("view_draw work", sum(self.timings.values()))
            if not self.display_warm and work <= WARM_DISPLAY_WORK * self.progressive.budget:
                self.display_warm = True
                blank = gpu.types.GPUTexture((1, 1), format="RGBA32F",
                                             data=gpu.types.Buffer("FLOAT", 4, [0.0] * 4))
                self._quad(blank, ((-1, -1), (-0.99, -1), (-1, -0.99), (-0.99, -0.99)))
            return False
        self._quad(self.texture, self.corners)
        return True

    @staticmethod
    def _quad(texture, corners) -> None:
        from mathutils import Matrix

        shader = gpu.shader.from_builtin("IMAGE")
        batch = batch_for_shader(shader, "TRI_STRIP", {"pos": corners,
                                                       "texCoord": ((0, 0), (1, 0), (0, 1), (1, 1))})
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix.Identity(4))
            shader.bind()
            shader.uniform_sampler("image", texture)
            batch.draw(shader)


def draw_may_write() -> bool:
    """May a draw write Blender data? Not in Blender's UI: ``RenderEngine.view_draw`` is not
    ``FUNC_ALLOW_WRITE`` (a write raises "Writing to ID classes in this context is not
    allowed"), so a snapshot is left to the timer (``viewport_session.tick``). In background
    mode (tests, benchmarks) there is no such rule and no timer."""
    return bool(bpy.app.background)


def draw_view(renderer: ViewportRenderer, scene, depsgraph, view_matrix, window_matrix,
              region_width: int, region_height: int, bind=None, unbind=None,
              redraw=None, border=None) -> bool:
    """What ``view_draw`` does (module doc, steps 1–4) for a region of that size; tests call
    it with a camera's matrices into a ``GPUOffScreen``. bind / unbind : called around the
    texture draw (the engine's display-space shader); redraw : asks for another draw (the
    engine's ``tag_redraw``) while the image has not converged; border : the Render Region
    (``render_border``), whose pixels alone are traced and drawn. Returns whether anything was
    drawn."""
    view_settings = scene.voxgi_viewport
    view = _matrix(view_matrix)
    window, width, height, corners = view_frame(_matrix(window_matrix), region_width,
                                                region_height, view_settings.resolution_fraction,
                                                border)
    camera_key = (view.tobytes(), window.tobytes(), width, height)
    pass_name = VIEWPORT_PASSES[view_settings.viewport_pass]
    live = live_gi(scene.name_full)
    read = 0.0
    if live.reading is not None:
        # a full snapshot's mesh reads, a slice a draw, and the snapshot after the last: the
        # draw's work (nothing traced or prepared in it; the last image stays), the next
        # draw asked for
        t0 = time.perf_counter()
        # (the snapshot after the last read writes data: the timer takes it in Blender's UI)
        live.read_on(scene, depsgraph, snapshot=draw_may_write())
        read = time.perf_counter() - t0
        if redraw is not None:
            redraw()
    if width < 1:  # the Render Region lies outside the view: nothing to trace or draw
        renderer.status = live.view_status = "VoxGI | The Render Region is outside the view"
        return False
    renderer.frame_corners = corners
    if camera_key != renderer.view_key:
        renderer.view_key = camera_key
        live.view_changed(camera_from_view(view, window, width, height), scene, depsgraph)
    if live.world_only is not None:  # a view layer that shows no mesh: its world alone
        if not read:
            renderer.world.step(renderer, live.world_only, view, window, width, height,
                                camera_key, bool(scene.render.film_transparent),
                                pixel_filter_width(scene), redraw)
        renderer.shown = "World"
        return _shown(renderer, scene, live, bind, unbind)
    renderer.world.cancel()
    traced = ""
    progressive = renderer.progressive
    live.held_source = None
    source = live.image_source(scene.voxgi.quality)
    if source is not None and scene.voxgi.quality == "ACCURATE":
        # a frame being prepared is finished and shown before a newer one (what this draw's
        # slices trace too: ``LiveGI.image_source`` gives it)
        held = viewport_prepare.hold_source(live, source, renderer.shown_version)
        live.held_source, source = (None if held is source else held), held
    elif scene.voxgi.quality != "ACCURATE":
        viewport_prepare.preparation.hold = None  # (Fast traces the applied voxels)
    if source is not None and not read:
        options = base_options(scene.voxgi, width, height)
        if scene.voxgi.quality != "ACCURATE" and options["gather_settings"].bounces > 1:
            # Fast's voxels with the last complete cache's bounces, made on the worker: the
            # image restarts when they are there (viewport_bounces), not when the cache is
            renderer.bounced = renderer.bounces.current(live, renderer.cache.cache)
            cache_version = ("bounced voxels", renderer.bounces.version)
        else:
            # a completed radiance cache restarts the image (viewport_cache: the gathers read
            # the last complete cache while a new one is built)
            live.bounce_cache = renderer.bounced = None
            cache_version = ("cache", renderer.cache.generation)
        key = renderer.trace_key(source[2], camera_key, scene, pass_name, options) \
            + (cache_version,)
        if key != progressive.key:
            # only the radiance cache came in (the view, the scene and the settings as they
            # were): the image so far stays the backdrop until the tiles cover it, with no
            # coarse image of its own (a fresh view traced two: docs/gi_pipeline.md "A coarse
            # image sized by its whole work")
            cache_only = progressive.key is not None and key[:-1] == progressive.key[:-1]
            # Combined on the film, as F12's: the world behind the geometry (preview.film)
            progressive.restart(key, pass_name, width, height, view_settings.samples,
                                view_settings.coarse_first and not cache_only,
                                film=pass_name == "Combined",
                                transparent=bool(scene.render.film_transparent),
                                world=source[0].world)
        generation = renderer.cache.generation
        blend = gpu.state.blend_get()
        # The trace rasterizes its G-buffer: with the caller's blending on (view_draw's state)
        # its triangles blended into the cleared targets and the image was 3% off F12's.
        gpu.state.blend_set("NONE")
        try:
            traced = renderer.refine(live, scene, view, window)
            renderer.error = progressive.failed  # "" unless this key's slice failed before
        except Exception as error:  # noqa: BLE001 - keep drawing the last image, say why
            renderer.error = f"viewport trace failed: {type(error).__name__}: {error}"
            live.error = progressive.failed = renderer.error  # no retry until a change
        gpu.state.blend_set(blend)
        # "Refining" after convergence: a chunk of the radiance cache's build ran (its
        # completion restarts the image on the next draw). A build may also complete inside
        # a slice's cache stage, the slice that converged the image with the old cache: the
        # key is the next draw's to change, so that draw must come.
        if redraw is not None and (traced and (not progressive.converged
                                               or traced == "Refining"
                                               or renderer.cache.building is not None)
                                   or renderer.cache.generation != generation):
            if traced == "Preparing" and not renderer.prepare.timings:
                # nothing to do but wait for the preparing thread: drawn again once it
                # has moved on, the cores left to it meanwhile
                viewport_prepare.wake_later(redraw)
            else:
                redraw()  # the next slice on the next draw
    if source is not None and not read and scene.voxgi.quality == "ACCURATE":
        key = progressive.key
        viewport_prepare.hold_traced(live, source, None if key is None else key[0],
                                     renderer.shown_version)
    live.held_source = None  # (only this draw's slices trace what the view holds)
    if read:
        renderer.timings = {"snapshot read": read}
    if traced:
        renderer.shown = traced
    elif renderer.texture is None:
        renderer.shown = ""
    elif progressive.converged and progressive.key is not None and not renderer.error:
        renderer.shown = "Cached"
    else:  # a failed trace, or nothing applied yet: the last image stays
        renderer.shown = "Previous"
    return _shown(renderer, scene, live, bind, unbind)


def _shown(renderer: ViewportRenderer, scene, live, bind, unbind) -> bool:
    """``draw_view``'s end: the status line, then the shown texture drawn."""
    renderer.status = status_line(renderer, scene, live)
    live.view_status, live.view_shown = renderer.status, renderer.shown
    progressive = renderer.progressive
    live.view_samples = (progressive.samples_done, progressive.target)
    if bind is not None:
        bind()
    try:
        return renderer.draw()
    finally:
        if unbind is not None:
            unbind()


QUALITY_NAMES = {"ACCURATE": "Accurate", "FAST": "Fast"}


def status_line(renderer: ViewportRenderer, scene, live) -> str:
    """The view's status, as Cycles': 'VoxGI | Sample 3/16 | 1.24 s | Tile 5/12 | Accurate'
    while refining ('Coarse image' first), 'VoxGI | Sample 16/16 | Converged in 6.10 s |
    Accurate' at the end; a running job or an error is added."""
    quality = QUALITY_NAMES.get(scene.voxgi.quality, scene.voxgi.quality.title())
    if renderer.error:
        return f"VoxGI | {renderer.error}"
    progressive = renderer.progressive
    shown = renderer.shown
    samples = f"Sample {progressive.samples_done}/{progressive.target}"
    if shown == "World":
        return "VoxGI | The world alone: the view layer shows no mesh"
    if shown in ("Preparing", "Quick"):  # viewport_prepare: the scene, the batch, the kernels
        line = f"VoxGI | {renderer.prepare.status} | {quality}"
    elif shown == "":
        line = "VoxGI | Waiting for the first GI update"
    elif shown == "Previous":
        line = f"VoxGI | Previous image | {quality}"
    elif progressive.converged:
        line = f"VoxGI | {samples} | Converged in {progressive.elapsed:.2f} s | {quality}"
    else:
        line = (f"VoxGI | {samples} | {progressive.elapsed:.2f} s | {progressive.stage()} | "
                f"{quality}")
    textures = len(live.bakes.requests)
    if textures:
        line += f" | Baking {textures} material texture{'s' if textures > 1 else ''}…"
    if live.bakes.worlds.pending:
        line += " | Baking the world…"
    if live.running is not None:
        line += " | Updating GI…"
    return line


PANORAMIC_NOTE = (" | A panoramic camera is drawn as perspective here (F12 renders perspective "
                  "and orthographic cameras: Camera properties > Lens > Type)")


def camera_note(context, scene) -> str:
    """What the header adds in the camera view of a panoramic camera: Blender hands the view a
    perspective projection there, which the view traces, where Cycles' view traces the
    panorama (F12 stops with the same advice: ``camera.check_camera_type``)."""
    region_data = getattr(context, "region_data", None)
    camera = scene.camera
    if getattr(region_data, "view_perspective", None) == "CAMERA" and camera is not None \
            and getattr(camera.data, "type", "PERSP") == "PANO":
        return PANORAMIC_NOTE
    return ""


def view_update(engine, context, depsgraph) -> None:
    """``RenderEngine.view_update``: plan and schedule the depsgraph's updates."""
    scene = depsgraph.scene_eval.original
    live = live_gi(scene.name_full)
    if not getattr(engine, "voxgi_entered", False):
        # a new engine (Rendered mode entered again, another 3D view): the updates made while
        # no engine listened were not seen, so everything is read again (the caches'
        # fingerprints still decide what is voxelized; snapshot/mesh_cache.py)
        engine.voxgi_entered = True
        viewport_prepare.preparation.hold = None  # a new view holds no earlier frame
        if live.index is not None:
            live.rescan = live.rescan or "Rendered mode entered"
    # a new snapshot's GPU scene is prepared on the worker at once, ahead of the update job
    # (viewport_prepare; removed by ``release``)
    if viewport_prepare.prepare_snapshot not in SNAPSHOT_HOOKS:
        SNAPSHOT_HOOKS.append(viewport_prepare.prepare_snapshot)
    region_data = getattr(context, "region_data", None)
    region = getattr(context, "region", None)
    if live.view_camera is None and region_data is not None and region is not None:
        window, width, height, _ = view_frame(
            _matrix(region_data.window_matrix), region.width, region.height,
            scene.voxgi_viewport.resolution_fraction, render_border(context, scene, depsgraph))
        if width >= 1:
            live.view_camera = camera_from_view(_matrix(region_data.view_matrix), window,
                                                width, height)
    # draws follow: a full snapshot's mesh reads go on in them, a slice each (``draw_view``)
    live.read_slice = READ_SLICE
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
              region.width, region.height, bind=bind, unbind=unbind, redraw=engine.tag_redraw,
              border=render_border(context, scene, depsgraph))
    engine.update_stats("", renderer.status + camera_note(context, scene))  # the header


def release() -> None:
    """Free every viewport's textures and atlas, and the prepared scene (unregister, exit)."""
    for renderer in list(_renderers):
        renderer.free()
    viewport_prepare.release()
    if viewport_prepare.prepare_snapshot in SNAPSHOT_HOOKS:
        SNAPSHOT_HOOKS.remove(viewport_prepare.prepare_snapshot)


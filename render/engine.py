"""The "VoxGI" render engine (Render Properties › Render Engine).

F12 / ``bpy.ops.render.render()`` renders the GI preview of the scene camera into Cycles-named
passes (registered with ``register_pass``, so they reach the compositor and multilayer EXR
output): the scene is snapshotted, the session's voxel caches transformed (voxelizing first if
needed), and the passes traced on the GPU (``gpu_preview``) inside the engine's GPU context,
or with the numpy tracer when that fails (reported). ``bl_use_gpu_context`` gives the context
even in background mode. In the 3D view's Rendered mode ``view_update`` / ``view_draw`` show
live GI (``viewport.py``).
"""
from __future__ import annotations

import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..blender.session import scene_session
from ..blender.settings import pixel_filter_width
from ..blender.snapshot.bakes import render_bakes
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.preview.film import snapshot_combined
from ..voxgi_addon.preview.passes import PASS_NAMES
from . import gpu_context
from .pipeline import render_scene_passes

# Our passes other than Combined → (Blender's view-layer toggle, channels).
EXTRA_PASSES = {
    "Diffuse Direct": "use_pass_diffuse_direct",
    "Diffuse Indirect": "use_pass_diffuse_indirect",
    "Diffuse Color": "use_pass_diffuse_color",
    "Glossy Direct": "use_pass_glossy_direct",
    "Glossy Indirect": "use_pass_glossy_indirect",
    "Glossy Color": "use_pass_glossy_color",
    "Ambient Occlusion": "use_pass_ambient_occlusion",
}


def enable_passes(view_layer) -> None:
    """Turn on the view-layer toggles of our passes (so the compositor offers them)."""
    for toggle in EXTRA_PASSES.values():
        setattr(view_layer, toggle, True)


def frame_size(scene) -> tuple[int, int]:
    render = scene.render
    return (max(1, render.resolution_x * render.resolution_percentage // 100),
            max(1, render.resolution_y * render.resolution_percentage // 100))


def render_region(scene, width: int, height: int) -> tuple[int, int, int, int] | None:
    """(x0, y0, w, h), pixels from the bottom left, of the part of a ``width`` × ``height``
    frame that Blender's render result holds with Render Region on (Output › Format, Ctrl B in
    the camera view): the region's pixels as Blender cuts them (its float corners times the
    size, truncated), cropped or not (Blender puts a region into the whole frame itself); None
    without a region, or when it is the whole frame."""
    render = scene.render
    if not render.use_border:
        return None

    def cut(low, high, size):  # Blender's float32 product, truncated to an int
        a, b = int(np.float32(low) * np.float32(size)), int(np.float32(high) * np.float32(size))
        a = min(a, size - 1)
        return a, max(b, a + 1) - a
    (x0, w), (y0, h) = cut(render.border_min_x, render.border_max_x, width), \
        cut(render.border_min_y, render.border_max_y, height)
    return None if (w, h) == (width, height) else (x0, y0, w, h)


def render_views(scene) -> list[str | None]:
    """The views F12 renders: [None] (the one camera) unless Stereoscopy is on, then the left
    and right views (Stereo 3D) or every enabled view (Multi-View), by name."""
    render = scene.render
    if not render.use_multiview:
        return [None]
    names = [v.name for v in render.views if v.use and
             (render.views_format == "MULTIVIEW" or v.name in ("left", "right"))]
    return names or [None]


@dataclass
class Capture:
    """What an F12 run by ``voxgi.render_preview`` traced, kept for its EXR file: the passes
    (a Render Region's alone), the film's Combined, the report lines, or the error."""
    indirect_source: str | None = None  # 'CONES' / 'PROBES': the operator's; None: the scene's
    passes: dict | None = None
    combined: np.ndarray | None = None
    report: list = field(default_factory=list)
    error: str | None = None


_CAPTURES: dict[str, Capture] = {}


@contextmanager
def captured(scene, indirect_source: str | None = None):
    """Inside the block, F12 of ``scene`` (``bpy.ops.render.render()``) also keeps what it
    traced in the yielded ``Capture``, and reports through it alone."""
    capture = Capture(indirect_source)
    _CAPTURES[scene.name_full] = capture
    try:
        yield capture
    finally:
        _CAPTURES.pop(scene.name_full, None)


class VoxGIRenderEngine(bpy.types.RenderEngine):
    bl_idname = "VOXGI"
    bl_label = "VoxGI"
    bl_use_gpu_context = True
    bl_use_preview = False

    def update_render_passes(self, scene=None, renderlayer=None):
        for name in EXTRA_PASSES:
            self.register_pass(scene, renderlayer, name, 3, "RGB", "COLOR")

    # The 3D view's Rendered mode (render/viewport.py): plan and run updates on the worker,
    # trace and draw the view on the GPU. (render.register imports the module beforehand.)
    def view_update(self, context, depsgraph):
        from . import viewport
        viewport.view_update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        from . import viewport
        viewport.view_draw(self, context, depsgraph)

    def render(self, depsgraph):
        scene = depsgraph.scene
        if scene.name.startswith(gpu_context.BOOTSTRAP_SCENE):
            return  # ensure_gpu_context only needs this call to happen
        # each view of a stereo or multi-view render from its own camera (Blender's per view:
        # its model matrix and lens shift), into its own view of the result
        for view in render_views(scene):
            camera = None
            if view is not None and scene.camera is not None:
                self.active_view_set(view)
                camera = (np.array(self.camera_model_matrix(scene.camera), np.float64),
                          float(self.camera_shift_x(scene.camera)))
            # Esc ends a wait for bakes another process makes (F12 in the UI)
            with render_bakes.watching(self.test_break):
                if not self._render_view(scene, depsgraph, view, camera):
                    return

    def _render_view(self, scene, depsgraph, view, camera) -> bool:
        """Trace one view (``camera``: its (model matrix, lens shift x), None: the scene
        camera's) and send its passes; False when it failed (reported)."""
        width, height = frame_size(scene)
        # a Render Region is traced alone (with its filters' margin), as Cycles renders it
        region = render_region(scene, width, height)
        capture = _CAPTURES.get(scene.name_full)
        try:
            passes, report = render_scene_passes(
                bpy.context, scene, depsgraph, width, height,
                capture.indirect_source if capture is not None else None,
                view_camera=camera, region=region)
            # the film: the world behind the geometry, or alpha with Film › Transparent
            combined = snapshot_combined(scene_session(scene.name_full).snapshot, passes,
                                         pixel_filter_width(scene))
        except VoxGIError as error:
            if capture is not None:
                capture.error = str(error)
                return False
            self.report({"ERROR"}, f"VoxGI render failed: {error}")
            return False
        except Exception as error:  # a bug must fail this frame, never take Blender down
            traceback.print_exc()
            message = f"VoxGI render failed unexpectedly: {error!r} (see the console)"
            if capture is not None:
                capture.error = message
                return False
            self.report({"ERROR"}, message)
            return False
        if capture is not None:
            capture.passes, capture.combined, capture.report = passes, combined, report
        else:
            for level, line in report:
                self.report({level}, line)
        # Blender calls this once per view layer: the result of this one's layer alone (without
        # it, layers[0] is the first layer, which every view layer's image overwrote)
        size = (width, height) if region is None else region[2:]
        result = self.begin_result(0, 0, *size, layer=depsgraph.view_layer.name, view=view or "")
        layer = result.layers[0]
        for name in PASS_NAMES:
            render_pass = layer.passes.get(name)
            if render_pass is None:
                continue
            image = combined if name == "Combined" else passes[name]
            image = np.flipud(image)  # Blender's rows go bottom to top
            if render_pass.channels == 4 and image.shape[2] == 3:
                image = np.concatenate([image, np.ones(image.shape[:2] + (1,), np.float32)], axis=2)
            elif render_pass.channels == 3:
                image = image[:, :, :3]
            # one copy through the buffer protocol: assigning ``rect`` converts a pixel at a
            # time (1.1-1.4 s for a 640 x 480 frame's passes, against 15 ms)
            render_pass.rect.foreach_set(np.ascontiguousarray(image, np.float32).ravel())
        self.end_result(result)
        return True


classes = (VoxGIRenderEngine,)

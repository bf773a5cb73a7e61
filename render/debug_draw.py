"""Debug views drawn with ``gpu``: voxels or octree nodes as shaded cubes, cascade bounds as
wire boxes, over the 3D view in any shading mode (``ui/debug_draw.py`` owns the draw handler).

One instanced draw for all cubes: a batch of three unit-cube faces (+x, +y, +z; 18 vertices)
and a 2D RGBA32F texture with two texels per instance (centre + edge, colour), fetched with
the instance index. The vertex shader mirrors the three faces towards the eye, so the three
faces a cube shows are drawn and the three it hides never reach the rasterizer (half the
vertices of a full cube and no culling needed). Shaders are built once per process; the
instance texture and the bounds batch are rebuilt only when what they show changes
(``DebugDrawer.key``). ``gpu.state`` is restored after drawing.

**In slices, kept between draws** (issue 19 point 3): 250 000 cubes took 0.6–1 s per draw on
llvmpipe, every redraw. The cubes are drawn into the drawer's own *layer* (a colour and a
depth texture of the view's size) a slice of instances per draw (``draw_instances``:
``instance_start`` … ``+ count``, one batch), sized from measured times toward
``SLICE_BUDGET`` (``SliceSizer``, its per-instance cost measured with the slice's pixels
read); every draw puts the layer over the view with its depth (``gl_FragDepth``, so the
scene's own surfaces still hide cubes behind them). The layer is keyed by the instances, the
view's matrices and its size: an unchanged view draws no cube at all, only the layer; a
changed one clears it and fills it again slice by slice (``draw_debug`` says whether more
slices are to come, the caller asks for a redraw); the instances are in ``spread`` order, so a
view still filling in shows a thinner cloud of all of them, not one corner. The slices' depth test keeps the one
batch's order, so the full layer is the image one batch draws.
"""
from __future__ import annotations

import time
import weakref

import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..voxgi_addon.preview.debug_instances import (
    cascade_bounds,
    cascade_instances,
    octree_instances,
    pack_instances,
    spread,
)
from ..voxgi_addon.preview.progressive import SliceSizer

# seconds of cubes one draw aims at: the share of a draw's 30 ms the GI view's stages get
# (render/progressive.py SLICE_BUDGET × STAGE_SHARE, not imported: importing the tracer's
# module with the debug view made the process crash at exit; docs/gi_pipeline.md "Slices
# sized by their tail, stages predicted by their longest runs"): the layer put over the view
# with its depth costs 5–14 ms of the draw on its own, and at 20 ms of cubes the longest
# draws of a million cubes ran 35 ms
SLICE_BUDGET = 0.015
FIRST_SLICE = 4096    # instances of the first slice, before any was measured
LEAST_SLICE = 4096    # the fewest instances a slice draws

_VERTEX = """
void main()
{
  int texel = 2 * (first + gl_InstanceID); /* gl_InstanceID does not count instance_start */
  ivec2 at = ivec2(texel % columns, texel / columns);
  vec4 place = texelFetch(instances, at, 0);
  vec4 colour = texelFetch(instances, at + ivec2(1, 0), 0);
  vec3 centre = place.xyz;
  /* Towards the eye: a point (perspective) or a direction (orthographic, w = 0). */
  vec3 to_eye = eye.w > 0.5 ? eye.xyz - centre : eye.xyz;
  vec3 flip = vec3(to_eye.x < 0.0 ? -1.0 : 1.0, to_eye.y < 0.0 ? -1.0 : 1.0,
                   to_eye.z < 0.0 ? -1.0 : 1.0);
  vec3 world = centre + position * flip * place.w;
  gl_Position = view_projection * vec4(world, 1.0);
  vec3 n = normalize(normal * flip);
  float shade = 0.6 + 0.4 * abs(dot(n, normalize(vec3(0.3, 0.5, 0.8))));
  cube_colour = vec4(colour.rgb * shade, 1.0);
}
"""
_FRAGMENT = """
void main()
{
  out_colour = cube_colour;
}
"""

_LAYER_VERTEX = """
void main()
{
  uv = position * 0.5 + 0.5;
  gl_Position = vec4(position, 0.0, 1.0);
}
"""
_LAYER_FRAGMENT = """
void main()
{
  ivec2 at = ivec2(uv * vec2(textureSize(layer_depth, 0)));
  float depth = texelFetch(layer_depth, at, 0).r;
  if (depth >= 1.0) {
    discard; /* no cube here: the view as it is */
  }
  out_colour = texelFetch(layer_colour, at, 0);
  gl_FragDepth = depth;
}
"""

_shader = None
_layer_shader = None
_drawers: "weakref.WeakSet[DebugDrawer]" = weakref.WeakSet()


def cube_shader():
    """The instanced cube shader (built once)."""
    global _shader
    if _shader is None:
        varying = gpu.types.GPUStageInterfaceInfo("voxgi_debug_cube")
        varying.flat("VEC4", "cube_colour")
        info = gpu.types.GPUShaderCreateInfo()
        info.vertex_in(0, "VEC3", "position")
        info.vertex_in(1, "VEC3", "normal")
        info.vertex_out(varying)
        info.sampler(0, "FLOAT_2D", "instances")
        info.push_constant("MAT4", "view_projection")
        info.push_constant("VEC4", "eye")
        info.push_constant("INT", "columns")
        info.push_constant("INT", "first")
        info.fragment_out(0, "VEC4", "out_colour")
        info.vertex_source(_VERTEX)
        info.fragment_source(_FRAGMENT)
        _shader = gpu.shader.create_from_info(info)
    return _shader


def layer_shader():
    """The shader that puts a layer (colour + depth textures) over the view (built once)."""
    global _layer_shader
    if _layer_shader is None:
        varying = gpu.types.GPUStageInterfaceInfo("voxgi_debug_layer")
        varying.smooth("VEC2", "uv")
        info = gpu.types.GPUShaderCreateInfo()
        info.vertex_in(0, "VEC2", "position")
        info.vertex_out(varying)
        info.sampler(0, "FLOAT_2D", "layer_colour")
        info.sampler(1, "FLOAT_2D", "layer_depth")
        info.fragment_out(0, "VEC4", "out_colour")
        info.depth_write("ANY")
        info.vertex_source(_LAYER_VERTEX)
        info.fragment_source(_LAYER_FRAGMENT)
        _layer_shader = gpu.shader.create_from_info(info)
    return _layer_shader


def draw_instances(batch, shader, start: int, count: int) -> None:
    """Draw ``count`` instances of ``batch`` from instance ``start`` (one GPU draw; tests count
    them). The shader's ``first`` is the start: ``gl_InstanceID`` counts from 0 whatever
    ``instance_start`` is."""
    shader.uniform_int("first", int(start))
    batch.draw_instanced(shader, instance_start=0, instance_count=count)


def _three_faces():
    """(18, 3) positions and normals of the +x, +y, +z faces of a unit cube at the origin."""
    positions, normals = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        quad = []
        for a, b in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
            p = [0.0, 0.0, 0.0]
            p[axis], p[u], p[v] = 0.5, a, b
            quad.append(p)
        for i in (0, 1, 2, 0, 2, 3):
            positions.append(quad[i])
            normals.append([1.0 if k == axis else 0.0 for k in range(3)])
    return np.array(positions, np.float32), np.array(normals, np.float32)


BOUND_COLOURS = ((1.0, 0.55, 0.1, 1.0), (0.2, 0.8, 1.0, 1.0), (0.6, 1.0, 0.3, 1.0),
                 (1.0, 0.3, 0.8, 1.0))


class DebugDrawer:
    """The GPU objects of the debug views of one scene's results."""

    def __init__(self):
        self.key = None
        self.instances = None     # texture of the packed instances
        self.columns = 0
        self.count = 0
        self.bounds_key = None
        self.bounds_batch = None
        self.builds = 0           # how many times the instance texture was rebuilt
        self._cube = None
        self._state = None
        # the layer: the cubes drawn so far for one view (colour, depth, framebuffer)
        self.layer = None
        self.layer_key = None
        self.layer_drawn = 0      # instances in the layer
        self.sizer = SliceSizer(SLICE_BUDGET, first_pixels=FIRST_SLICE, least=LEAST_SLICE,
                                amortize=False)
        self.fixed_slice: int | None = None  # tests: every slice this many instances
        self.last_slice = 0       # instances the last draw drew
        self._quad = None
        _drawers.add(self)

    def free(self) -> None:
        self.instances = self.bounds_batch = self._cube = self._state = None
        self.key = self.bounds_key = None
        self.count = 0
        self.layer = self.layer_key = self._quad = None
        self.layer_drawn = 0

    def _cube_batch(self):
        if self._cube is None:
            positions, normals = _three_faces()
            self._cube = batch_for_shader(cube_shader(), "TRIS",
                                          {"position": positions, "normal": normals})
        return self._cube

    def prepare(self, state, view: str, cascade: int, level: int, colour: str) -> int:
        """Build the instance texture for this choice unless it already holds it; returns the
        number of cubes."""
        key = (view, cascade, level, colour)
        if key == self.key and state is self._state:  # ``is``: a freed state's id may recur
            return self.count
        self.key, self._state = key, state
        if view == "VOXELS":
            inst = cascade_instances(state, cascade, colour)
        else:
            inst = octree_instances(state.octree, level, colour)
        texels, self.columns = pack_instances(spread(inst))  # every slice over all of them
        flat = texels.ravel()
        self.instances = gpu.types.GPUTexture((self.columns, texels.shape[0]), format="RGBA32F",
                                              data=gpu.types.Buffer("FLOAT", flat.size, flat))
        self.count = len(inst)
        self.builds += 1
        return self.count

    def draw_cubes(self, view_projection, eye, start: int = 0, count: int | None = None) -> None:
        """Draw the prepared cubes (``count`` of them from ``start``; all when None) into the
        bound framebuffer. view_projection : (4, 4) world → clip; eye : (4,) the eye's
        position with w = 1 (perspective) or the direction to it with w = 0 (orthographic)."""
        count = self.count - start if count is None else min(count, self.count - start)
        if count <= 0:
            return
        shader = cube_shader()
        shader.bind()
        shader.uniform_sampler("instances", self.instances)
        shader.uniform_float("view_projection", _gl_matrix(view_projection))
        shader.uniform_float("eye", tuple(float(v) for v in eye))
        shader.uniform_int("columns", self.columns)
        draw_instances(self._cube_batch(), shader, start, count)

    def slice_size(self) -> int:
        """Instances the next slice draws (measured: ``SliceSizer``), at most twice the largest
        slice measured: slices of a few thousand cubes differ by less than the noise of a
        loaded machine, and a fit of noise once asked for 225 000 cubes (0.9 s) in one draw."""
        if self.fixed_slice is not None:
            return max(1, self.fixed_slice)
        largest = max((pixels for pixels, _ in self.sizer.samples), default=FIRST_SLICE)
        return min(self.sizer.pixels(self.count), 2 * largest)

    def draw_layer(self, view_projection, eye) -> bool:
        """Add the next slice of the prepared cubes to the layer of this view (a new view,
        size or set of cubes clears it first), then put the layer over the bound framebuffer
        with its depth. Returns True while cubes are still to be drawn into it."""
        x, y, width, height = gpu.state.viewport_get()
        key = (self.key, id(self._state), self.builds, np.asarray(view_projection).tobytes(),
               tuple(eye), width, height)
        if self.layer is None or self.layer[0].width != width or self.layer[0].height != height:
            colour = gpu.types.GPUTexture((width, height), format="RGBA16F")
            depth = gpu.types.GPUTexture((width, height), format="DEPTH_COMPONENT32F")
            self.layer = (colour, depth,
                          gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=colour))
            self.layer_key = None
        colour, depth, framebuffer = self.layer
        if key != self.layer_key:
            self.layer_key, self.layer_drawn = key, 0
            with framebuffer.bind():
                framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        self.last_slice = 0
        if self.layer_drawn < self.count:
            count = min(self.slice_size(), self.count - self.layer_drawn)
            t0 = time.perf_counter()
            with framebuffer.bind():
                gpu.state.viewport_set(0, 0, width, height)
                self.draw_cubes(view_projection, eye, self.layer_drawn, count)
                # one pixel read: the slice's rasterization is done (llvmpipe defers it), so
                # the time measured is the slice's
                framebuffer.read_color(0, 0, 1, 1, 4, 0, "FLOAT")
            gpu.state.viewport_set(x, y, width, height)
            if self.fixed_slice is None:
                self.sizer.measured(count, time.perf_counter() - t0)
            self.layer_drawn += count
            self.last_slice = count
        shader = layer_shader()
        if self._quad is None:
            self._quad = batch_for_shader(shader, "TRI_STRIP",
                                          {"position": ((-1, -1), (1, -1), (-1, 1), (1, 1))})
        shader.bind()
        shader.uniform_sampler("layer_colour", colour)
        shader.uniform_sampler("layer_depth", depth)
        self._quad.draw(shader)
        return self.layer_drawn < self.count

    def draw_bounds(self, grids, view_projection) -> None:
        key = tuple((g.index, g.span, g.resolution, tuple(g.origin)) for g in grids)
        if key != self.bounds_key:
            self.bounds_key = key
            shader = gpu.shader.from_builtin("FLAT_COLOR")
            lines = cascade_bounds(grids)
            colours = np.repeat(np.array([BOUND_COLOURS[g.index % len(BOUND_COLOURS)]
                                          for g in grids], np.float32), 24, axis=0)
            self.bounds_batch = batch_for_shader(shader, "LINES", {"pos": lines, "color": colours})
        shader = gpu.shader.from_builtin("FLAT_COLOR")
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            from mathutils import Matrix

            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix(np.asarray(view_projection).tolist()))
            self.bounds_batch.draw(shader)


def _gl_matrix(m) -> list[float]:
    """A (4, 4) row-major matrix as the column-major floats ``uniform_float`` takes."""
    return np.asarray(m, np.float32).T.ravel().tolist()


def draw_debug(drawer: DebugDrawer, state, settings, view_projection, eye,
               redraw=None) -> int:
    """Draw ``state`` as ``settings`` (``Scene.voxgi_viewport``) ask, with depth testing,
    restoring ``gpu.state``: the cubes a slice per call into the drawer's layer, which is put
    over the view (``DebugDrawer.draw_layer``); ``redraw()`` is called while slices are to
    come (None: the area being drawn is tagged). Returns the number of cubes shown when
    complete."""
    view = settings.debug_view
    if state is None or (view == "NONE" and not settings.show_bounds):
        return 0
    blend, depth_test, depth_mask = gpu.state.blend_get(), gpu.state.depth_test_get(), \
        gpu.state.depth_mask_get()
    count = 0
    try:
        gpu.state.blend_set("NONE")
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(True)
        if view != "NONE":
            count = drawer.prepare(state, view, settings.debug_cascade, settings.debug_level,
                                   settings.debug_colour)
            if drawer.draw_layer(view_projection, eye):
                _ask_redraw(redraw)
        if settings.show_bounds:
            drawer.draw_bounds(state.grids, view_projection)
    finally:
        gpu.state.blend_set(blend)
        gpu.state.depth_test_set(depth_test)
        gpu.state.depth_mask_set(depth_mask)
    return count


_redraw_pending = False


def _ask_redraw(redraw) -> None:
    """``redraw()``, or (None) tag the 3D views for a redraw from a timer: a region being
    drawn ignores a redraw tagged from its own draw handler."""
    global _redraw_pending
    if redraw is not None:
        redraw()
        return
    if _redraw_pending:
        return
    import bpy

    def tag():
        global _redraw_pending
        _redraw_pending = False
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        return None  # once

    _redraw_pending = True
    bpy.app.timers.register(tag, first_interval=0.0)


def eye_of(view_matrix, window_matrix) -> tuple[float, float, float, float]:
    """The eye for ``draw_cubes`` from a view's matrices."""
    inverse = np.linalg.inv(np.asarray(view_matrix, np.float64))
    if abs(np.asarray(window_matrix)[3, 3] - 1.0) < 1e-9:  # orthographic: towards the viewer
        return (*inverse[:3, 2], 0.0)
    return (*inverse[:3, 3], 1.0)


def release() -> None:
    """Free every drawer's textures and batches and drop the cached shader (unregister, exit:
    docs/gi_pipeline.md "GPU resources at exit")."""
    global _shader, _layer_shader
    for drawer in list(_drawers):
        drawer.free()
    gpu.shader.unbind()  # (gpu_shaders.forget)
    _shader = _layer_shader = None

"""Debug views drawn with ``gpu``: voxels or octree nodes as shaded cubes, cascade bounds as
wire boxes, over the 3D view in any shading mode (``ui/debug_draw.py`` owns the draw handler).

One instanced draw for all cubes: a batch of three unit-cube faces (+x, +y, +z; 18 vertices)
and a 2D RGBA32F texture with two texels per instance (centre + edge, colour), fetched with
the instance index. The vertex shader mirrors the three faces towards the eye, so the three
faces a cube shows are drawn and the three it hides never reach the rasterizer (half the
vertices of a full cube and no culling needed). Shaders are built once per process; the
instance texture and the bounds batch are rebuilt only when what they show changes
(``DebugDrawer.key``). ``gpu.state`` is restored after drawing.
"""
from __future__ import annotations

import weakref

import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..voxgi_addon.preview.debug_instances import (
    cascade_bounds,
    cascade_instances,
    octree_instances,
    pack_instances,
)

_VERTEX = """
void main()
{
  int texel = 2 * gl_InstanceID;
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

_shader = None
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
        info.fragment_out(0, "VEC4", "out_colour")
        info.vertex_source(_VERTEX)
        info.fragment_source(_FRAGMENT)
        _shader = gpu.shader.create_from_info(info)
    return _shader


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
        _drawers.add(self)

    def free(self) -> None:
        self.instances = self.bounds_batch = self._cube = self._state = None
        self.key = self.bounds_key = None
        self.count = 0

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
        texels, self.columns = pack_instances(inst)
        flat = texels.ravel()
        self.instances = gpu.types.GPUTexture((self.columns, texels.shape[0]), format="RGBA32F",
                                              data=gpu.types.Buffer("FLOAT", flat.size, flat))
        self.count = len(inst)
        self.builds += 1
        return self.count

    def draw_cubes(self, view_projection, eye) -> None:
        """Draw the prepared cubes. view_projection : (4, 4) world → clip; eye : (4,) the eye's
        position with w = 1 (perspective) or the direction to it with w = 0 (orthographic)."""
        if not self.count:
            return
        shader = cube_shader()
        shader.bind()
        shader.uniform_sampler("instances", self.instances)
        shader.uniform_float("view_projection", _gl_matrix(view_projection))
        shader.uniform_float("eye", tuple(float(v) for v in eye))
        shader.uniform_int("columns", self.columns)
        self._cube_batch().draw_instanced(shader, instance_start=0, instance_count=self.count)

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


def draw_debug(drawer: DebugDrawer, state, settings, view_projection, eye) -> int:
    """Draw ``state`` as ``settings`` (``Scene.voxgi_viewport``) ask, with depth testing,
    restoring ``gpu.state``; returns the number of cubes drawn."""
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
            drawer.draw_cubes(view_projection, eye)
        if settings.show_bounds:
            drawer.draw_bounds(state.grids, view_projection)
    finally:
        gpu.state.blend_set(blend)
        gpu.state.depth_test_set(depth_test)
        gpu.state.depth_mask_set(depth_mask)
    return count


def eye_of(view_matrix, window_matrix) -> tuple[float, float, float, float]:
    """The eye for ``draw_cubes`` from a view's matrices."""
    inverse = np.linalg.inv(np.asarray(view_matrix, np.float64))
    if abs(np.asarray(window_matrix)[3, 3] - 1.0) < 1e-9:  # orthographic: towards the viewer
        return (*inverse[:3, 2], 0.0)
    return (*inverse[:3, 3], 1.0)


def release() -> None:
    """Free every drawer's textures and batches and drop the cached shader (unregister, exit:
    docs/gi_pipeline.md "GPU resources at exit")."""
    global _shader
    for drawer in list(_drawers):
        drawer.free()
    _shader = None

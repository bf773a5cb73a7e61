"""Primary visibility on the GPU: rasterize the scene's triangles into a G-buffer.

The same per-pixel answers as ``voxgi_addon.scene.raycast.primary_visibility`` (pixel-centre rays
or all moved by one sub-pixel offset,
shading normals turned to the camera by the face normal, the camera's clipping range), by
rasterizing ``scene_geometry.world_triangles`` with ``raycast.view_projection`` into three
RGBA32F textures that the cone-tracing kernels read directly. GPU images are stored bottom
row first (OpenGL); ``read_gbuffer`` flips them to the passes' top-first order.
"""
from __future__ import annotations

import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..voxgi_addon.preview.lobe_footprint import FOOTPRINT_LIMIT, footprint_variance
from ..voxgi_addon.scene.camera import (
    DEFAULT_FILTER_WIDTH,
    camera_frame,
    filter_offsets,
    view_projection,
)
from ..voxgi_addon.scene.snapshot import RAY_CAMERA
from ..voxgi_addon.scene.textures import (
    FOOTPRINT_COS_MIN,
    METALLIC_LEVELS,
    ROUGHNESS_LEVELS,
    filter_footprint,
    pixel_spread,
    pixel_steps,
    unpack_emission,
)
from .gpu_shaders import SHADER_DIR, create_shader
from .gpu_tracer import read_texture


def gbuffer_shader(textured: bool = True):
    """A new G-buffer raster shader; textured False: the plain variant, without the code that
    samples textures (gbuffer_frag.glsl RASTER_TEXTURES), for a scene none of whose materials
    has one (``GPUScene.raster_textures()`` None): its fragments cost 4–5× less on llvmpipe.
    Not cached between renders: a raster shader (and the vertex
    arrays Blender keeps with it) belongs to the GPU context it was made in, and the next F12,
    preview or viewport draw may run in another (after a file load, between F12's and the
    operators' contexts), where a cached one rasterized a partial G-buffer
    (docs/gi_pipeline.md, "One file's state"). A render makes one and passes it to its
    ``rasterize`` calls."""
    varying = gpu.types.GPUStageInterfaceInfo("voxgi_gbuffer")
    varying.smooth("VEC3", "world_position")
    varying.smooth("VEC3", "shading_normal")
    varying.flat("VEC3", "flat_normal")
    varying.flat("VEC2", "surface")
    varying.smooth("VEC2", "surface_uv")
    varying.flat("VEC2", "surface_slot")
    varying.flat("VEC2", "surface_cutout")
    varying.flat("VEC2", "surface_params")
    varying.flat("VEC2", "surface_normal_map")
    varying.flat("VEC4", "surface_tangent")
    varying.flat("VEC4", "surface_glow")
    varying.flat("VEC3", "surface_base")
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC3", "position")
    info.vertex_in(1, "VEC3", "normal")
    info.vertex_in(2, "VEC3", "face_normal")
    info.vertex_in(3, "VEC2", "material")
    info.vertex_in(4, "VEC2", "uv")
    info.vertex_in(5, "VEC2", "texel")
    info.vertex_in(6, "VEC2", "cutout")
    info.vertex_in(7, "VEC2", "params")
    info.vertex_in(8, "VEC2", "normal_map")
    info.vertex_in(9, "VEC4", "tangent")
    info.vertex_in(10, "VEC4", "glow")
    info.vertex_in(11, "VEC3", "material_base")
    info.vertex_out(varying)
    info.sampler(0, "FLOAT_2D", "texture_table")
    info.sampler(1, "FLOAT_2D", "texture_atlas")
    info.define("FOOTPRINT_COS_MIN", repr(float(FOOTPRINT_COS_MIN)))
    info.define("ROUGHNESS_LEVELS", str(ROUGHNESS_LEVELS))
    info.define("METALLIC_LEVELS", str(METALLIC_LEVELS))
    info.push_constant("MAT4", "view_projection")
    info.push_constant("VEC3", "camera_position")
    info.push_constant("VEC3", "camera_forward")
    info.push_constant("FLOAT", "camera_ortho")
    info.push_constant("FLOAT", "pixel_spread")
    info.push_constant("FLOAT", "normal_footprint")
    info.define("FOOTPRINT_LIMIT", repr(float(FOOTPRINT_LIMIT)))
    taps = ""
    if textured:
        info.define("RASTER_TEXTURES", "1")
        # the texture taps' data in a uniform block (``_tap_block``): with them the push
        # constants would pass the 128 bytes a GPU must allow
        info.typedef_source("struct TapData { vec4 taps; vec4 offsets; vec4 step_x; "
                            "vec4 step_y; };\n")
        info.uniform_buf(0, "TapData", "tap_data")
        taps = ("#define texture_taps (tap_data.taps.xy)\n#define tap_shift (tap_data.taps.zw)\n"
                "#define tap_offsets (tap_data.offsets)\n"
                "#define pixel_step_x (tap_data.step_x.xyz)\n"
                "#define pixel_step_y (tap_data.step_y.xyz)\n")
    info.fragment_out(0, "VEC4", "out_position")
    info.fragment_out(1, "VEC4", "out_normal")
    info.fragment_out(2, "VEC4", "out_view")
    info.fragment_out(3, "VEC4", "out_base")
    info.vertex_source((SHADER_DIR / "gbuffer_vert.glsl").read_text())
    info.fragment_source(taps + (SHADER_DIR / "sampling.glsl").read_text() +
                         (SHADER_DIR / "textures.glsl").read_text() +
                         (SHADER_DIR / "gbuffer_frag.glsl").read_text())
    return create_shader(info, "gbuffer raster" if textured else "gbuffer raster (plain)")


class PixelMask:
    """The pixels a render's sub-pixel G-buffers need (the edge pixels its passes list): each
    such ``rasterize`` first writes depth 0 everywhere else (one full-screen triangle whose
    fragments are discarded at the needed pixels), so the scene's fragments there fail the
    depth test before the G-buffer shader runs: llvmpipe tests depth ahead of the fragment
    shader even with its ``discard`` (a textured room's 640 × 480 raster 78 ms, 12 ms with every
    pixel masked). The needed pixels get the same fragments as without a mask. Worth it for
    the textured raster only: the plain variant's fragments cost less than the mask's pass.
    keep : (H, W) bool, row 0 the top. Like ``gbuffer_shader``'s, its shader and batch belong
    to the render that makes them."""

    def __init__(self, keep):
        from .gpu_volume import float_texture

        keep = np.asarray(keep, bool)
        height, width = keep.shape
        self.texture = float_texture(np.flipud(keep).astype(np.float32), (width, height), "R32F")
        info = gpu.types.GPUShaderCreateInfo()
        info.vertex_in(0, "VEC2", "corner")
        info.sampler(0, "FLOAT_2D", "keep")
        for slot, name in enumerate(("out_position", "out_normal", "out_view", "out_base")):
            info.fragment_out(slot, "VEC4", name)
        info.vertex_source("void main() { gl_Position = vec4(corner, -1.0, 1.0); }")
        info.fragment_source(
            "void main() {\n"
            "  if (texelFetch(keep, ivec2(gl_FragCoord.xy), 0).x > 0.5) { discard; }\n"
            "  out_position = out_normal = out_view = out_base = vec4(0.0);\n}\n")
        self.shader = create_shader(info, "gbuffer pixel mask")
        self.batch = batch_for_shader(self.shader, "TRIS",
                                      {"corner": [(-1.0, -1.0), (3.0, -1.0), (-1.0, 3.0)]})

    def draw(self) -> None:
        """Depth 0 at the pixels not kept (the bound framebuffer, its viewport set)."""
        gpu.state.depth_test_set("ALWAYS")
        gpu.state.depth_mask_set(True)
        self.shader.bind()
        self.shader.uniform_sampler("keep", self.texture)
        self.batch.draw(self.shader)


def _reads(shader, name: str) -> bool:
    """Whether ``shader`` has the uniform or sampler ``name`` (the compiler drops the ones its
    code does not read: the plain variant's texture and camera-footprint inputs)."""
    try:
        return shader.uniform_from_name(name) >= 0
    except ValueError:
        return False


class GBuffer:
    """position, normal, view : RGBA32F textures (see module doc) of width × height; base :
    (Base Color sampled per texel, 1) where the pixel's material has a texture, else 0; where
    it has an emission texture, (its Base Color, the emission per texel packed into one float
    ≥ 2: ``scene.textures.pack_emission``)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        self.position = gpu.types.GPUTexture((width, height), format="RGBA32F")
        self.normal = gpu.types.GPUTexture((width, height), format="RGBA32F")
        self.view = gpu.types.GPUTexture((width, height), format="RGBA32F")
        self.base = gpu.types.GPUTexture((width, height), format="RGBA32F")
        self.depth = gpu.types.GPUTexture((width, height), format="DEPTH_COMPONENT32F")

    @property
    def inputs(self) -> dict[str, object]:
        return {"gbuffer_position": self.position, "gbuffer_normal": self.normal,
                "gbuffer_view": self.view, "gbuffer_base": self.base}


def rasterize(tris, camera, roughness: np.ndarray, width: int, height: int,
              offset=(0.0, 0.0), shader=None, textures=None,
              filter_width: float = DEFAULT_FILTER_WIDTH, batch=None, out=None,
              mask: PixelMask | None = None, texture_taps: int = 1,
              texture_share: int = 1, supersample: int = 1, into=None,
              tap_shift=(0.0, 0.0)) -> GBuffer:
    """Draw ``tris`` (``SceneTriangles``) seen by ``camera`` into a new ``GBuffer``.
    batch : ``vertex_batch(tris, roughness, shader, textures is not None)`` made already by a
    render that draws them again, or a ``ChunkedBatch`` of them (the viewport's: only its
    chunks inside the view are drawn); None: made here.

    roughness : (M + 1,) per material index (last = no material), as ``preview`` tables it.
    offset : (x, y) pixels (x right, y down): every pixel sees what the camera ray that far
    from its centre sees (``camera.camera_rays``' offset; one sub-pixel pass).
    shader : the render's ``gbuffer_shader`` (None: a new one for this call).
    textures : (texture table, atlas) GPU textures of ``tris.textures`` (``gpu_scene``'s
    ``textures`` part): the fragment samples each textured material's Base Color per texel at
    ``scene.textures.primary_lod`` (Filter Size ``filter_width``) into ``base``; None: no
    texture is sampled. Fragments of cut-outs are kept by their Alpha (level 0) against a
    hash of the fragment's point, view and triangle (``textures.cutout_random``), as camera
    rays pass them in ``raycast``. A material with Roughness / Metallic per texel writes the
    material variant of the fragment's texel (``textures.SurfaceTextures.variant_at``) and its
    roughness; a normal map perturbs the fragment's shading normal
    (``textures.SurfaceTextures.normal_at``). A material with an emission texture writes its
    Base Color (per texel or its value) and its emission per texel at its own
    ``primary_lod``, packed into base's 4th channel (``textures.pack_emission``: a float ≥ 2,
    so kernels that test w > 0.5 for a textured Base Color read it as before).
    out : a GBuffer of this size drawn before with the same camera: drawn into, not cleared
    (the viewport's quick image, a part of its chunks per draw).
    mask : only its pixels drawn (``PixelMask``; the others hold nothing), with a new GBuffer.
    texture_taps, texture_share : ``textures.primary_base``'s ``taps`` (the Base Color's taps
    per axis over each pixel's own square, 1–4: ``TEXTURE_TAPS`` for the pixel-centre pass)
    and ``share`` (a sub-pixel pass is one of ``AA_SIDE``² samples of its pixel).
    tap_shift : (x, y) pixels (x right, y down) the taps' square is moved by from each
    fragment's own camera ray: a view's sample whose camera is moved by o sub-pixel
    (``progressive.sample_offset``) gives −o, so its taps stand on its pixel's own square, as
    F12's centre pass's do, whatever o (docs/gi_pipeline.md "A sample's textures over its
    pixel's square").
    supersample : K, a G-buffer of K·width × K·height: the image's pixels each drawn at K × K
    points (texel (K·x + i, K·y + j) at pixel (x, y) + offset + ((i + ½) / K − ½, (j + ½) / K −
    ½), x right and y down), the textures' footprints still the image pixel's (every sample one
    of ``texture_share``² of its pixel). One raster for K² sub-pixel passes: a 140k-triangle
    scene's raster is its vertices' work, 50–90 ms whatever its size. The mask is then K times
    the image's size too.
    into : a GBuffer whose content is no longer needed: cleared and drawn into when it has
    this size (the sub-pixel passes' rasters, one after another: a new one's five textures
    took 34 ms at 640 × 480 and 60 ms at 1280 × 720 to make), else a new one is made.
    """
    fresh = out is None
    size = (width * supersample, height * supersample)
    if fresh:
        out = into if into is not None and (into.width, into.height) == size else GBuffer(*size)
    framebuffer = gpu.types.GPUFrameBuffer(depth_slot=out.depth,
                                           color_slots=(out.position, out.normal, out.view,
                                                        out.base))
    rotation, position = camera_frame(camera)
    matrix = view_projection(camera, width * supersample, height * supersample,
                             (offset[0] * supersample, offset[1] * supersample))
    shader = shader or gbuffer_shader()
    with framebuffer.bind():
        if fresh:
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        if len(tris):
            gpu.state.viewport_set(0, 0, width * supersample, height * supersample)
            if mask is not None and fresh:
                mask.draw()
            gpu.state.depth_test_set("LESS")
            gpu.state.depth_mask_set(True)
            gpu.state.face_culling_set("NONE")
            if batch is None:
                batch = _new_batch(tris, roughness, shader, textures is not None)
            if textures is None or getattr(tris, "textures", None) is None:
                textures = _no_textures()
            shader.bind()
            if _reads(shader, "texture_table"):  # (not the plain variant)
                shader.uniform_sampler("texture_table", textures[0])
                shader.uniform_sampler("texture_atlas", textures[1])
                # (held until the draw: the shader keeps no reference to the block)
                tap_block = _tap_block(camera, width, height, filter_width, texture_taps,
                                       texture_share, tap_shift)
                shader.uniform_block("tap_data", tap_block)
            for name, value in (
                    ("view_projection", matrix.T.ravel().tolist()),
                    ("camera_position", position.astype(np.float32)),
                    ("camera_forward", (-rotation[:, 2]).astype(np.float32)),
                    ("camera_ortho", 1.0 if camera.type == "ORTHO" else 0.0),
                    ("pixel_spread", float(pixel_spread(camera, width, height) *
                                           filter_footprint(filter_width))),
                    # σ² of the lobe's footprint in this raster's texels (lobe_footprint)
                    ("normal_footprint", footprint_variance(filter_width, texture_share) *
                     supersample * supersample)):
                if _reads(shader, name):  # (the plain variant reads fewer)
                    shader.uniform_float(name, value)
            if isinstance(batch, ChunkedBatch):
                batch.draw_visible(shader, matrix)
            else:
                batch.draw(shader)
            gpu.state.depth_test_set("NONE")
            gpu.state.depth_mask_set(False)
            # unbound: Blender's context remembers its bound shader by address and skips the
            # next bind of the same address, and this shader (and the mask's) is freed with its
            # render; a later render's new raster shader made at that address then drew with
            # the freed one's program and last camera (docs/gi_pipeline.md "One file's state")
            gpu.shader.unbind()
            # the raster done now, not at a later read or the draw's end: llvmpipe defers a
            # raster's work to the next use of its targets, so a viewport step that drew this
            # ended in a few ms while its raster landed, unmeasured, in the draw's last
            # milliseconds (docs/gi_pipeline.md "Worker threads below the main thread, steps
            # timed to their rasters' end")
            framebuffer.read_color(0, 0, 1, 1, 4, 0, "FLOAT")
    return out



def _tap_block(camera, width: int, height: int, filter_width: float, taps: int, share: int,
               shift=(0.0, 0.0)):
    """The textured G-buffer shader's uniform block ``tap_data`` (``TapData``): texture_taps
    (taps per axis, share) and tap_shift (``rasterize``'s), tap_offsets (the offsets along one axis,
    ``camera.filter_offsets``) and the pixel steps (``textures.pixel_steps``)."""
    block = np.zeros((4, 4), np.float32)
    for row, (_, value) in enumerate(_tap_uniforms(camera, width, height, filter_width, taps,
                                                   share, shift)):
        block[row, :len(value)] = value
    return gpu.types.GPUUniformBuf(block.ravel())


def _tap_uniforms(camera, width: int, height: int, filter_width: float, taps: int, share: int,
                  shift=(0.0, 0.0)):
    """The G-buffer shader's texture_taps (taps per axis, share, then tap_shift), tap_offsets (the offsets
    along one axis, ``camera.filter_offsets``) and pixel steps (``textures.pixel_steps``)."""
    taps = int(taps) if filter_width > 0.0 else 1
    if not 1 <= taps <= 4:
        raise ValueError(f"texture_taps {taps} outside 1-4")
    along = np.zeros(4, np.float32)
    if taps > 1:
        along[:taps] = filter_offsets(filter_width, taps)[::taps, 0]
    steps = pixel_steps(camera, width, height).astype(np.float32)
    return (("texture_taps", (float(taps), float(max(int(share), 1)), float(shift[0]),
                              float(shift[1]))), ("tap_offsets", along),
            ("pixel_step_x", steps[0]), ("pixel_step_y", steps[1]))


class ChunkedBatch:
    """``vertex_batch``'s triangles as several batches of consecutive triangles (``batches``)
    with their world-space bounds ((lo, hi) each, ``bounds``): ``rasterize`` draws only the
    chunks whose bounds reach into its view, so a tile of the view draws what it can see
    (the same fragments: a triangle in view is in a chunk in view). The viewport fills one a
    chunk per draw (``viewport_prepare``)."""

    def __init__(self, batches=(), bounds=()):
        self.batches, self.bounds = list(batches), list(bounds)

    def part(self, first: int, end: int) -> ChunkedBatch:
        """The chunks first … end − 1."""
        return ChunkedBatch(self.batches[first:end], self.bounds[first:end])

    def visible(self, matrix) -> list[int]:
        """The chunks inside the clip volume of ``matrix`` (view-projection, (4, 4)): a chunk
        is left out when all 8 corners of its box lie outside one clip plane."""
        matrix = np.asarray(matrix, np.float64)
        inside = []
        for index, (lo, hi) in enumerate(self.bounds):
            corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                for z in (lo[2], hi[2])])
            clip = corners @ matrix.T
            w = clip[:, 3]
            if not any(np.all(clip[:, axis] > w) or np.all(clip[:, axis] < -w)
                       for axis in range(3)):
                inside.append(index)
        return inside

    def draw_visible(self, shader, matrix) -> int:
        """Draw the chunks inside the clip volume of ``matrix`` (``visible``); how many."""
        inside = self.visible(matrix)
        for index in inside:
            self.batches[index].draw(shader)
        return len(inside)


def rasterize_stages(tris, camera, roughness, width: int, height: int, offset=(0.0, 0.0),
                     shader=None, textures=None, filter_width: float = DEFAULT_FILTER_WIDTH,
                     batch=None, texture_taps: int = 1, tap_shift=(0.0, 0.0)):
    """``rasterize`` as a generator of stages returning the ``GBuffer``: with a
    ``ChunkedBatch`` (the viewport's) it yields after each chunk in view is drawn, so a
    scene's G-buffer goes over several draws (140k triangles: 60–80 ms of llvmpipe's vertex
    work in one); any other batch is drawn in the one call."""
    if not isinstance(batch, ChunkedBatch) or len(batch.batches) <= 1:
        return rasterize(tris, camera, roughness, width, height, offset, shader, textures,
                         filter_width, batch, texture_taps=texture_taps, tap_shift=tap_shift)
    inside = batch.visible(view_projection(camera, width, height, offset))
    out = rasterize(tris, camera, roughness, width, height, offset, shader, textures,
                    filter_width, batch.part(inside[0], inside[0] + 1) if inside
                    else ChunkedBatch(), texture_taps=texture_taps,
                    tap_shift=tap_shift)  # cleared, the first chunk
    for index in inside[1:]:
        yield
        rasterize(tris, camera, roughness, width, height, offset, shader, textures,
                  filter_width, batch.part(index, index + 1), out=out, texture_taps=texture_taps,
                  tap_shift=tap_shift)
    return out


def vertex_batch(tris, roughness, shader, textured: bool = True):
    """The vertex batch ``rasterize`` draws ``tris`` with, for ``shader``: a render that draws
    the same triangles several times (the sub-pixel passes' G-buffers) makes it once and
    hands it to each ``rasterize`` (rebuilding and uploading it for each of a preview's 17
    G-buffers took 0.45 s each on a 0.45 M-triangle scene). It lives as long as the render
    holds it: kept across renders, a batch drawn after its GPU context had changed crashed
    Blender."""
    return _new_batch(tris, roughness, shader, textured)

def _new_batch(tris, roughness, shader, textured: bool):
    """``vertex_batch``, built from ``vertex_arrays`` (those ``shader`` reads: the plain
    variant reads no texture attribute)."""
    names = {name for name, _ in shader.attrs_info_get()}
    arrays = vertex_arrays(tris, roughness, textured)
    return batch_for_shader(shader, "TRIS", {name: value for name, value in arrays.items()
                                             if name in names})


def vertex_arrays(tris, roughness, textured: bool) -> dict[str, np.ndarray]:
    """The attributes of ``vertex_batch`` by name (numpy only, any thread: the viewport makes
    them on the worker and fills its batch an attribute per draw): per corner its position,
    normals, (material, roughness), and the texture attributes of ``textured`` triangles
    (level-0 densities per metre; the camera's footprint is the shader's ``pixel_spread``)."""
    material = np.asarray(tris.materials)
    material = np.where((material >= 0) & (material < len(roughness) - 1), material,
                        len(roughness) - 1)
    corners = np.asarray(tris.positions, np.float32).reshape(-1, 3)
    face = np.repeat(np.asarray(tris.normals, np.float32), 3, axis=0)
    smooth = face if tris.corner_normals is None else \
        np.asarray(tris.corner_normals, np.float32).reshape(-1, 3)
    surface = np.repeat(np.stack([material, roughness[material]], axis=1)
                        .astype(np.float32), 3, axis=0)
    # Cycles' ray visibility and holdouts, as raycast.primary_visibility: a triangle
    # camera rays do not see is drawn degenerate (no fragment); a holdout's fragments
    # hide what is behind them and leave the pixel empty (material -2, gbuffer_frag).
    seen = tris.accepted(RAY_CAMERA) if hasattr(tris, "accepted") else None
    if seen is not None:
        corners = corners.reshape(-1, 3, 3).copy()
        corners[~seen] = corners[~seen][:, :1]
        corners = corners.reshape(-1, 3)
    if getattr(tris, "holdout", None) is not None:
        surface[np.repeat(np.asarray(tris.holdout), 3), 0] = -2.0
    surface_textures = getattr(tris, "textures", None)
    if surface_textures is not None:  # glass: opaque to camera rays (scene.glass)
        surface_textures = surface_textures.for_camera()
    # (alpha texture, alpha value) of cut-outs (textures.cutout_hits), -2: opaque
    cutout = np.tile(np.float32([-2.0, 1.0]), (len(corners), 1))
    # (parameter texture, first variant) of Roughness / Metallic per texel, -1: none
    params = np.tile(np.float32([-1.0, 0.0]), (len(corners), 1))
    # (normal map texture, Strength) and the triangle's tangent (textures.normal_at)
    normal_map = np.tile(np.float32([-1.0, 1.0]), (len(corners), 1))
    tangent = np.zeros((len(corners), 4), np.float32)
    # (emission texture, Strength, its texels per metre × the footprint, 0) and the
    # material's Base Color value (textures.SurfaceTextures.emission_at), -1: none
    glow = np.tile(np.float32([-1.0, 0.0, 0.0, 0.0]), (len(corners), 1))
    material_base = np.zeros((len(corners), 3), np.float32)
    if not textured or surface_textures is None:
        uv = np.zeros((len(corners), 2), np.float32)
        texel = np.tile(np.float32([-1.0, 0.0]), (len(corners), 1))
    else:
        uv = np.asarray(surface_textures.uvs, np.float32).reshape(-1, 2)
        # (slot, level-0 texels per metre; × pixel_spread in gbuffer_vert.glsl)
        texel = np.repeat(np.stack(
            [surface_textures.slot_of(tris.materials).astype(np.float32),
             surface_textures.density], axis=1), 3, axis=0)
        if surface_textures.cutout is not None:
            row = surface_textures.row_of(tris.materials)
            cutout = np.repeat(np.stack(
                [np.where(surface_textures.cutout, surface_textures.alpha_slots[row], -2),
                 surface_textures.alpha_values[row]], axis=1).astype(np.float32), 3, axis=0)
        if surface_textures.param_slots is not None:
            row = surface_textures.row_of(tris.materials)
            params = np.repeat(np.stack(
                [surface_textures.param_slots[row], surface_textures.variants[row]],
                axis=1).astype(np.float32), 3, axis=0)
        if surface_textures.normal_slots is not None:
            row = surface_textures.row_of(tris.materials)
            normal_map = np.repeat(np.stack(
                [surface_textures.normal_slots[row], surface_textures.normal_strength[row]],
                axis=1).astype(np.float32), 3, axis=0)
            tangent = np.repeat(np.asarray(surface_textures.tangents, np.float32), 3,
                                axis=0)
        if surface_textures.emission_slots is not None:
            row = surface_textures.row_of(tris.materials)
            glow = np.repeat(np.stack(
                [surface_textures.emission_slots[row],
                 surface_textures.emission_strength[row],
                 surface_textures.emission_density,
                 np.zeros(len(row))], axis=1).astype(np.float32), 3, axis=0)
            material_base = np.repeat(np.asarray(
                surface_textures.material_base, np.float32)[row], 3, axis=0)
    return {"position": corners, "normal": smooth, "face_normal": face, "material": surface,
            "uv": uv, "texel": texel, "cutout": cutout, "params": params,
            "normal_map": normal_map, "tangent": tangent, "glow": glow,
            "material_base": material_base}


def _no_textures():
    """A (table, atlas) pair of 1 × 1 textures for a render with no texture to sample."""
    blank = gpu.types.Buffer("FLOAT", 4, [0.0, 0.0, 0.0, 0.0])
    return (gpu.types.GPUTexture((1, 1), format="RGBA32F", data=blank),
            gpu.types.GPUTexture((1, 1), format="RGBA32F", data=blank))


def read_gbuffer(gbuffer: GBuffer) -> dict[str, np.ndarray]:
    """The G-buffer as top-row-first numpy arrays: hit (H, W) bool, position, normal,
    direction (H, W, 3) float32, roughness (H, W) float32, material (H, W) int32, base
    (H, W, 3) and textured (H, W) bool, emission (H, W, 3) per texel where emissive (H, W)
    bool (``textures.unpack_emission``), holdout (H, W) bool: a holdout hides what is behind
    (position.w = -1, ``gbuffer_frag.glsl``)."""
    position = np.flipud(read_texture(gbuffer.position))
    normal = np.flipud(read_texture(gbuffer.normal))
    view = np.flipud(read_texture(gbuffer.view))
    base = np.flipud(read_texture(gbuffer.base))
    hit = position[..., 3] > 0.5
    return {"hit": hit, "position": position[..., :3], "normal": normal[..., :3],
            "roughness": normal[..., 3], "direction": view[..., :3],
            "material": np.where(hit, np.rint(view[..., 3]), -1).astype(np.int32),
            "base": base[..., :3], "textured": base[..., 3] > 0.5,
            "emission": unpack_emission(base[..., 3]), "emissive": base[..., 3] > 1.5,
            "holdout": position[..., 3] < -0.5}

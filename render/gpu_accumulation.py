"""The viewport's progressive sums on the GPU (issue 19: the frame stays on the GPU).

``GPUAccumulation`` is ``voxgi_addon/preview/progressive.Accumulation`` (the readable numpy
reference it is tested against) with its sums in two textures: a sample's terms go in by a
compute kernel (``shaders/accumulate.glsl``) and the shown image comes out of another
(``shaders/estimate.glsl``), so a slice of the Rendered view reads nothing back:

* Accurate's tracer hands over its sums of one pass through the pixel centres as textures
  (``GPUSums``, ``gpu_preview.render_passes_stages(on_gpu=True)``); ``shaders/pass_sample.glsl``
  turns them into the pass's terms (``progressive.sample_terms``);
* passes that come as numpy images (Fast quality, whose cones are composed on the CPU; a view
  with glass, whose two layers are composed on the CPU; tests) are turned into the same terms
  by ``sample_terms`` and uploaded;
* the world along the tile's camera rays (``film.world_along``) is uploaded with the tile.

Nothing here runs without a GPU context (the viewport's ``view_draw`` has one).
"""
from __future__ import annotations

import dataclasses
import math

import gpu
import numpy as np

from ..voxgi_addon.preview.passes import PASS_NAMES
from ..voxgi_addon.preview.progressive import (
    GATHERED,
    LIGHT_COLOURS,
    TEXTURE_STEP,
    inside,
    sample_terms,
)
from ..voxgi_addon.preview.upsample import PLANE_TOLERANCE
from .gpu_scene import GPUScene
from .gpu_shaders import LOCAL_SIZE, build_compute, forget
from .gpu_volume import float_texture

zeros = GPUScene.zeros  # cleared on the GPU: nothing uploaded (an upload cost 4 ms a restart)
LAYERS = 5  # accumulate.glsl's layers: sums, weights, gathered light, film, holdout
# pass_sample.glsl's kind per pass
PASS_KINDS = {"Combined": 0, "Diffuse Direct": 1, "Diffuse Indirect": 2, "Glossy Direct": 3,
              "Glossy Indirect": 4, "Diffuse Color": 5, "Glossy Color": 6,
              "Ambient Occlusion": 7}
SUM_NAMES = ("sum_a", "sum_b", "sum_c", "sum_d", "sum_e", "sum_f", "sum_g")
_shaders: dict[str, object] = {}


@dataclasses.dataclass
class GPUSums:
    """One pass through the pixel centres of a ``width`` × ``height`` image, as the GPU tracer
    summed it (``gpu_preview._accurate_stages``: SUM_NAMES → RGBA32F textures, rows bottom to
    top, the channels of ``preview.passes.SUMS``), never read back."""

    textures: dict
    width: int
    height: int
    # the pixels' G-buffer (position, normal, view: gbuffer.GBuffer's) where the sums were
    # traced, for the film's mean weights within a surface (``GPUAccumulation.add``)
    surface: tuple | None = None


def _shader(name: str):
    """The compute shader ``name`` (accumulate, estimate, pass_sample), built once per process
    in the current GPU context."""
    if name not in _shaders:
        samplers, constants, outputs, read_write = {
            "pass_sample": (SUM_NAMES, ("kind",), ("out_value", "out_weight", "out_light"), ()),
            "accumulate": (("sample_value", "sample_weight", "sample_light", "world_image",
                            "centre_position", "centre_normal", "centre_view", "centre_base"),
                           ("rect", "window", "mode", "info", "tail_a", "tail_b", "tail_c"),
                           (), ("acc", "tails")),
            "estimate": (("acc", "tails", "backdrop"), ("window", "info", "mode"),
                         ("out_image",), ()),
        }[name]
        files = {"pass_sample": (name,), "accumulate": ("accumulation_common", "same_surface", name),
                 "estimate": ("accumulation_common", name)}[name]
        defines = {"PLANE_TOLERANCE": repr(float(PLANE_TOLERANCE)),
                   "TEXTURE_STEP": repr(float(TEXTURE_STEP))} if name == "accumulate" else None
        _shaders[name] = build_compute(files, samplers, constants, outputs, defines=defines,
                                       read_write=read_write)
    return _shaders[name]


def release() -> None:
    """Drop the cached shaders (at exit, or when the GPU context goes)."""
    forget(_shaders)


def _dispatch(shader, width: int, height: int) -> None:
    gpu.compute.dispatch(shader, max(1, math.ceil(width / LOCAL_SIZE)),
                         max(1, math.ceil(height / LOCAL_SIZE)), 1)


def _upload(image) -> object:
    """(h, w, 4) float32, row 0 on top → a texture (rows bottom to top)."""
    image = np.ascontiguousarray(np.flipud(np.asarray(image, np.float32)))
    return float_texture(image, (image.shape[1], image.shape[0]))


def read_rgba(texture) -> np.ndarray:
    """(H, W, 4) float32 of a texture, row 0 on top (tests and tools only: the viewport reads
    nothing back)."""
    from .gpu_tracer import read_texture

    return np.flipud(read_texture(texture))


def sample_textures(sample, pass_name: str, film: bool):
    """(value, weight, light) textures of one sample of ``pass_name`` (``accumulate.glsl``'s
    sample_*: pass_sample.glsl's layout) from a ``GPUSums`` (on the GPU) or numpy passes
    (``progressive.sample_terms``, uploaded); (width, height)."""
    if isinstance(sample, GPUSums):
        shader = _shader("pass_sample")
        out = {name: gpu.types.GPUTexture((sample.width, sample.height), format="RGBA32F")
               for name in ("out_value", "out_weight", "out_light")}
        shader.bind()
        for name in SUM_NAMES:
            shader.uniform_sampler(name, sample.textures[name])
        shader.uniform_float("kind", (float(PASS_KINDS[pass_name]), 0.0, 0.0, 0.0))
        for name, texture in out.items():
            shader.image(name, texture)
        _dispatch(shader, sample.width, sample.height)
        return (out["out_value"], out["out_weight"], out["out_light"]), \
            (sample.width, sample.height)
    if film and "Alpha" not in sample:
        raise ValueError("the film needs the passes' Alpha (surface coverage)")
    terms = sample_terms(sample, pass_name)
    height, width = terms["value"].shape[:2]
    alpha = np.asarray(sample.get("Alpha", np.zeros((height, width))), np.float32)
    holdout = np.asarray(sample.get("_holdout", np.zeros((height, width))), np.float32)
    return (_upload(np.dstack([terms["value"], alpha])),
            _upload(np.dstack([terms["weight"], holdout])),
            _upload(np.dstack([terms["light"], np.zeros((height, width), np.float32)]))), \
        (width, height)


class GPUAccumulation:
    """The samples of one pass of a ``width`` × ``height`` image on the GPU: ``Accumulation``'s
    sums (own and tails) in two RGBA32F textures of LAYERS stacked layers
    (``shaders/accumulate.glsl``). film / transparent : as ``Accumulation``'s."""

    def __init__(self, pass_name: str, width: int, height: int, film: bool = False,
                 transparent: bool = False):
        if pass_name not in PASS_NAMES:
            raise ValueError(f"unknown pass {pass_name!r}; one of {', '.join(PASS_NAMES)}")
        if width < 1 or height < 1:
            raise ValueError(f"an image of {width}×{height} pixels has nothing to accumulate")
        self.pass_name, self.width, self.height = pass_name, int(width), int(height)
        self.film, self.transparent = bool(film), bool(transparent)
        self._acc = self._tails = None  # made at the first use (an orbit restarts every draw)
        self.kind = 2 if pass_name == "Combined" else (1 if pass_name in LIGHT_COLOURS else 0)
        self.added = 0  # samples added (tiles of all samples)
        self._black = None

    def add(self, rect, sample, gather_weight: float = 1.0, tails=None, world=None,
            mean_tails=None, surface=None) -> None:
        """Add one sample of the tile ``rect`` (x0, y0 from the top, w, h): a ``GPUSums`` or
        numpy passes (PASS_NAMES → (h, w, 3), row 0 on top, with "Alpha" for the film), as
        ``Accumulation.add``: gather_weight, tails ((3, 3) the sample's filter weights in its
        neighbours, ``sample_tail_weights``; None: none), world ((h, w, 3) the world along the
        tile's camera rays, or None: black). mean_tails ((3, 3) ``passes.neighbour_weights``,
        with tails and the tile's G-buffer: surface, the (position, normal, view, base)
        textures of ``gbuffer.GBuffer``, or None: the sample's own, ``GPUSums.surface``): a
        pixel's sample goes into a neighbour of the tile across a step of one surface's
        texture by these instead of tails (``Accumulation.add``'s mean_tails)."""
        x0, y0, w, h = (int(v) for v in rect)
        (value, weight, light), size = sample_textures(sample, self.pass_name, self.film)
        if size != (w, h):
            raise ValueError(f"a {size[0]}×{size[1]} sample for a {w}×{h} tile")
        window, _ = inside((x0, y0, w, h), self.width, self.height)
        rows, cols = window
        if rows.start >= rows.stop or cols.start >= cols.stop:
            return  # the tile lies past the image
        grown = (max(cols.start - 1, 0), max(rows.start - 1, 0))
        grown = (*grown, min(cols.stop + 1, self.width) - grown[0],
                 min(rows.stop + 1, self.height) - grown[1])
        if world is not None and self.film:
            world_texture = _upload(np.dstack([np.asarray(world, np.float32)[..., :3],
                                               np.zeros((h, w), np.float32)]))
        else:
            world_texture = self._blank()
        spread = np.zeros(12, np.float32)
        if tails is not None:
            spread[:9] = np.asarray(tails, np.float32).reshape(9)
            spread[4] = 0.0  # the centre is the pixel's own sum
        surface = surface if surface is not None else getattr(sample, "surface", None)
        mean = 0.0
        if tails is not None and mean_tails is not None and surface is not None:
            mean = float(np.asarray(mean_tails)[1, 2])  # separable: a at the sides, a² corners
        else:
            surface = (self._blank(),) * 4
        shader = _shader("accumulate")
        shader.bind()
        for name, texture in zip(("sample_value", "sample_weight", "sample_light", "world_image",
                                  "centre_position", "centre_normal", "centre_view",
                                  "centre_base"),
                                 (value, weight, light, world_texture, *surface)):
            shader.uniform_sampler(name, texture)
        m = float(gather_weight) if self.pass_name in GATHERED else 1.0
        shader.uniform_float("rect", (float(x0), float(y0), float(w), float(h)))
        shader.uniform_float("window", tuple(float(v) for v in grown))
        shader.uniform_float("mode", (float(self.kind), m, float(gather_weight),
                                      1.0 if self.film else 0.0))
        shader.uniform_float("info", (float(self.width), float(self.height),
                                      1.0 if world is not None and self.film else 0.0, mean))
        for name, part in zip(("tail_a", "tail_b", "tail_c"), (spread[:4], spread[4:8],
                                                               spread[8:])):
            shader.uniform_float(name, tuple(float(v) for v in part))
        shader.image("acc", self.acc)
        shader.image("tails", self.tails)
        _dispatch(shader, grown[2], grown[3])
        self.added += 1

    @property
    def acc(self):
        """The sums: LAYERS layers of the image (``shaders/accumulate.glsl``)."""
        if self._acc is None:
            self._acc = zeros(self.width, LAYERS * self.height)
        return self._acc

    @property
    def tails(self):
        """The sums' tails over the neighbours, in the same layers."""
        if self._tails is None:
            self._tails = zeros(self.width, LAYERS * self.height)
        return self._tails

    def _blank(self):
        """A 1 × 1 texture of zeros bound where a sampler has nothing to read."""
        if self._black is None:
            self._black = zeros(1, 1)
        return self._black

    def _estimate(self, out, window, backdrop=None) -> None:
        x0, y0, w, h = window
        shader = _shader("estimate")
        shader.bind()
        # before the first sample (a coarse image's view over its backdrop) the sums hold
        # nothing: blanks are bound instead of making them (two W × 5H clears, 5–6 ms of the
        # coarse image's last draw at 320 × 180)
        empty = self.added == 0 and backdrop is not None
        shader.uniform_sampler("acc", self._blank() if empty else self.acc)
        shader.uniform_sampler("tails", self._blank() if empty else self.tails)
        back = backdrop if backdrop is not None else self._blank()
        shader.uniform_sampler("backdrop", back)
        shader.uniform_float("window", (float(x0), float(y0), float(w), float(h)))
        shader.uniform_float("info", (float(self.width), float(self.height), float(back.width),
                                      float(back.height)))
        shader.uniform_float("mode", (1.0 if self.film else 0.0,
                                      1.0 if self.transparent else 0.0, 0.0,
                                      2.0 if empty else 1.0 if backdrop is not None else 0.0))
        shader.image("out_image", out)
        _dispatch(shader, w, h)

    def estimate(self, backdrop=None):
        """A new (W, H) RGBA32F texture: the samples so far with their tails over the
        neighbours, on the film (``Accumulation.estimate_rgba``: at every sample the image
        filtered as F12's is), ``backdrop`` (a texture, any size) where no sample landed
        yet."""
        out = gpu.types.GPUTexture((self.width, self.height), format="RGBA32F")
        self._estimate(out, (0, 0, self.width, self.height), backdrop)
        return out

    def estimate_into(self, image, rect) -> None:
        """Refresh ``image`` (the last ``estimate``'s texture) where the tile ``rect`` changed
        it: its pixels and, by the tails, one pixel around (``Accumulation.estimate_into``)."""
        x0, y0, w, h = (int(v) for v in rect)
        window, _ = inside((x0 - 1, y0 - 1, w + 2, h + 2), self.width, self.height)
        rows, cols = window
        if rows.start < rows.stop and cols.start < cols.stop:
            self._estimate(image, (cols.start, rows.start, cols.stop - cols.start,
                                   rows.stop - rows.start))

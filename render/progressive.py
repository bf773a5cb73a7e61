"""Time-sliced, progressive drawing of the viewport's image: one bounded slice per
``view_draw`` (``viewport.py``).

An image of ``target`` samples (*Viewport Samples*) is traced in slices, each one call of the
one-shot GPU tracer (``gpu_preview.render_passes_gpu``, F12's kernels) over a small image:

1. **coarse**: the whole view at low resolution (about a slice's pixels), drawn at once so a
   changed view, scene or setting is never blank (with *Coarse First Image*; without it the
   previous image stays under the tiles until they cover it);
2. **tiles**: sample k of the full image, tile by tile: a tile is a rectangle of the image
   traced through its own off-axis camera (``preview.progressive.tile_camera``) with sample k's
   sub-pixel offset, seed and share of the rays (``sample_settings``), and added to the
   per-pixel sums on the GPU (``gpu_accumulation.GPUAccumulation``; numpy's
   ``preview.progressive.Accumulation`` is the reference it is tested against), and by Cycles'
   pixel filter at the sample's offset into the neighbours' tails, so the image shown after
   any tile is filtered as F12's is (the view reaches F12's error after fewer samples); the
   tile grid moves from sample to sample;
3. **the film** (Combined): every slice also looks the world up along its camera rays
   (``preview.film.world_along``) and the samples' coverage and holdout shares are summed
   with it (``film=True``), so the image shows the world behind the geometry —
   or, with Film › Transparent, alpha = coverage — as F12's film does (``preview.film``);
4. **converged** after ``target`` samples: nothing more is traced until the key changes.

The slice's pixels come from measured slice times (``SliceSizer``: a fixed cost per slice
plus a cost per pixel) so that one slice stays near ``SLICE_BUDGET``; a tile where the view's
cost map (``preview.tile_costs``) predicts one of its stages past the stage budget is cut in
two. The work one slice
dispatches is one tracer call over at most ``slice_pixels`` pixels (tests count the
dispatched work groups). The frame stays on the GPU: the tracer hands its sums over as
textures, the gathers are summed on the GPU (``gpu_gather_sums``) and the shown image is a
texture made from the sums (docs/gi_pipeline.md "The frame on the GPU").
"""
from __future__ import annotations

import dataclasses
import inspect
import math
import time

import numpy as np

from ..blender.settings import cone_settings, trace_options
from ..voxgi_addon.preview.film import world_along
from ..voxgi_addon.preview.passes import neighbour_weights
from ..voxgi_addon.preview.progressive import (
    SliceSizer,
    fit_side,
    gather_samples,
    sample_offset,
    sample_settings,
    sample_tail_weights,
    tile_camera,
    tile_grid,
    tile_shape,
    tile_side,
)
from ..voxgi_addon.preview.tile_costs import CostMap, split_to_fit
from ..voxgi_addon.scene.view_camera import camera_from_view
from .gpu_accumulation import GPUAccumulation, read_rgba
from .gpu_gather_sums import GPUGatherSums
from .gpu_shaders import LOCAL_SIZE, counters

SLICE_BUDGET = 0.030  # seconds one view_draw's slice aims at (issue 19)
STAGE_SHARE = 0.5     # of it, what a call's stages run until, and what the longest stage aims at
# of it, what a call's stages may reach with the next one, predicted by that stage's time in
# the last slice of its kind: the rest is view_draw's own work (key, texture draw, status)
# (half: every draw also pays the region's image at the GPU's finish, 8 ms idle and 12–25 ms
# under load, and a stage's raster work lands there too; docs/gi_pipeline.md "Entering
# Rendered mode")
WORK_SHARE = 0.5
UNTIMED_SHARE = 0.5  # of the stage budget: the least a stage never timed is taken to cost
# seconds of stages the coarse first image aims at in all, over its draws: the view waits for
# it (a view change's first image within 0.1 s: its draws also pay their own work and Blender's
# event loop between them). Sized by its longest stage, it was a quarter of the view and took
# 115-190 ms of stages over 9-12 draws on the demo scene at 1280 × 720 (docs/gi_pipeline.md
# "A coarse image sized by its whole work")
COARSE_WORK = 0.03
LEAST_TILE = 48       # pixels: about the smallest tile side (preview.progressive.tile_side)
# BVH traversals a gather invocation makes per dispatch in a slice (F12: 32): the gather of a
# tile is several steps, so the longest stage is no longer the gather's one dispatch and the
# tiles grow (docs/gi_pipeline.md "Viewport samples whose gathers end early")
SLICE_TRAVERSALS = 8
# slices of a kind whose stage times predict that stage in the next one: the longest of them,
# scaled up to the next slice's pixels (the last one's time alone let a tile cut by the
# image's border predict a whole tile's stage; draws ran to 35-50 ms)
STAGE_HISTORY = 4
# the first sample's diffuse gather at the lattice of its cells, with LATTICE_RAYS × its rays
# (voxgi_addon/preview/progressive.py; docs/gi_pipeline.md "The view's first sample at the
# lattice"): the view is first within Cycles' error of F12's image when that sample is whole
LATTICE_FIRST = True
MEAN_TAILS = True
# of the stage budget: a tile whose longest stage the view's cost map predicts past this is cut
# in two (``preview.tile_costs``): the emitters' stages cost two to ten times as much a pixel
# by the emissive room's panel as elsewhere, and a tile of the sample's one size there ran one
# stage to 30–45 ms (docs/gi_pipeline.md "Tiles split where they cost")
SPLIT_SHARE = 1.0


def base_options(settings, width: int, height: int) -> dict:
    """The tracer's options for the viewport's ``width`` × ``height`` image: F12's for that
    size, point-sampled per slice (the samples' sub-pixel offsets anti-alias it), every
    gather point traced (the samples accumulate the gathers; the sparse plan would read the
    G-buffer back in a slice's stage), the gathers' rays in steps of ``SLICE_TRAVERSALS``."""
    options = trace_options(settings, width, height)
    if options["quality"] == "ACCURATE":
        options["traversals"] = SLICE_TRAVERSALS
    return {**options, "filter_width": 0.0,
            "gather_settings": dataclasses.replace(options["gather_settings"], sparse=False)}


_sizers: dict[tuple[float, bool, str], SliceSizer] = {}


def shared_sizer(budget: float, amortize: bool = True, kind: str = "tile") -> SliceSizer:
    """The process's slice sizer for ``budget`` and slices of ``kind``: every view measures
    the same machine, so a 3D view switched to Rendered starts from what the others measured
    (the first one from the smallest tile). amortize : as ``SliceSizer``'s (False for staged
    slices). kind : "tile" for the samples that trace the gathers, "lit tile" for the later
    ones, which cost a fraction of a pixel's time (``sample_kind``): each its own fit."""
    if (budget, amortize, kind) not in _sizers:
        _sizers[budget, amortize, kind] = SliceSizer(
            budget, first_pixels=LEAST_TILE * LEAST_TILE, least=LEAST_TILE * LEAST_TILE,
            amortize=amortize)
    return _sizers[budget, amortize, kind]


@dataclasses.dataclass
class Slice:
    """What one slice traced: kind "coarse" or "tile", its rectangle of the image (the whole
    image for coarse), the traced size, the sample index, seconds."""

    kind: str
    rect: tuple[int, int, int, int]
    size: tuple[int, int]
    sample: int
    seconds: float = 0.0
    finished: bool = True  # False: a stage of a slice that goes on in the next call


class ProgressiveImage:
    """The accumulation of one view's image and the slices still to trace."""

    def __init__(self, budget: float = SLICE_BUDGET):
        # A slice runs over as many calls as its stages need: each call runs stages until it
        # has spent STAGE_SHARE of the budget, and the tiles are sized so that the longest
        # stage takes about that much (so a call stays within the budget)
        self.budget = budget
        self.sizers = {kind: shared_sizer(budget * STAGE_SHARE, amortize=False, kind=kind)
                       for kind in ("tile", "lit tile")}
        self.sizers["coarse"] = shared_sizer(COARSE_WORK, amortize=False, kind="coarse")
        self.stage_budget: float | None = budget * STAGE_SHARE  # None: a whole slice a call
        self.running = None        # the slice under way: a generator of its stages
        self.running_started = 0.0
        self.longest_stage = 0.0
        self.running_work = 0.0    # the slice under way's stages' seconds, summed
        # (slice kind, stage index) → (seconds, pixels) in the last STAGE_HISTORY slices of
        # that kind: a slice's stages come in the same order each time, so they predict the
        # next one's (``predicted``)
        self.stage_seconds: dict[tuple[str, int], list[tuple[float, int]]] = {}
        self.running_kind, self.running_stage = "", 0
        self.running_pixels = 0    # the slice under way's pixels (its tile's, the coarse's)
        self.running_rect = None   # the tile under way (None: the coarse image)
        self.costs: CostMap | None = None  # where the key's stages cost their time
        self.tile_stride = 1       # the gather stride the sample's tiles were made for
        self.fixed_pixels: int | None = None  # tests: every slice this many pixels
        self.key = None
        # the samples' sums and the shown image live on the GPU (gpu_accumulation): a slice
        # reads nothing back (issue 19)
        self.accumulation = None   # a GPUAccumulation
        self.gathers = None        # Accurate: the samples' raw gathers (a GPUGatherSums)
        self.backdrop = None       # a texture: what shows where no tile landed yet
        self.image = None          # the current estimate: an RGBA32F texture on the film
        self.film = False          # the image shows the film (Combined): the world, alpha
        self.world = None          # its WorldData (the applied snapshot's)
        self.target = 1
        self.sample = 0            # the sample being traced
        self.tiles: list = []      # its tiles still to trace
        self.tile_count = 0        # how many tiles the sample has
        self.started = 0.0         # when the key's accumulation started (perf_counter)
        self.elapsed = 0.0         # seconds from the start to the last slice's end
        self.slices = 0            # slices traced for this key
        self.last: Slice | None = None
        self.converged = False
        self.coarse_pending = False
        # the key before this one was replaced before its coarse image was shown (an orbit, a
        # slider drag: a new key every draw): the first draw of this key traces nothing
        self.skip_first = False
        self.failed = ""
        self.image_stale = True
        # options the coarse image overrides (the viewport's first image after entering
        # Rendered mode: ``viewport_prepare.ViewPreparation.first_image_options``)
        self.coarse_options: dict = {}
        # size → the coarse image's pixel-centre G-buffer drawn already (the viewport's quick
        # image's) or None; None: drawn by the slice
        self.coarse_centre = None

    # ------------------------------------------------------------------ planning

    def restart(self, key, pass_name: str, width: int, height: int, target: int,
                coarse: bool, film: bool = False, transparent: bool = False,
                world=None) -> None:
        """A new key: start over; the last estimate (scaled) stays the backdrop until the
        coarse image or the tiles replace it. film : show the film (``preview.film``: the
        ``WorldData`` ``world`` behind the geometry, or alpha = coverage when
        ``transparent``), as F12's Combined does."""
        previous = self.image
        # every draw a new key: a coarse image started in a draw would be dropped by the next
        # one (the view shows the last image either way), so a key that replaces one whose
        # coarse image never showed waits one draw: the view is still when that draw's
        # redraw comes with the same key
        self.skip_first = bool(coarse) and self.key is not None and self.coarse_pending
        if self.running is not None:
            self.running.close()  # the old key's slice: its textures go with it
            self.running = None
        self.key, self.target = key, max(1, int(target))
        self.accumulation = GPUAccumulation(pass_name, width, height, film, transparent)
        self.film, self.world = bool(film), world
        if self.gathers is not None:
            self.gathers.free()
        self.gathers = None
        self.backdrop = previous
        self.sample, self.tiles, self.tile_count = 0, [], 0
        if self.costs is None:
            self.costs = CostMap(width, height)
        else:
            self.costs.restart(width, height)
        self.started, self.elapsed, self.slices = time.perf_counter(), 0.0, 0
        self.converged, self.coarse_pending = False, bool(coarse)
        self.failed = ""  # why a slice of this key failed ("" = none): no retry until a change
        self.last = None
        self.image_stale = True  # ``image`` is another key's: the next slice rebuilds it

    @property
    def sizer(self) -> SliceSizer:
        """The slice sizer of the sample being traced (``sample_kind``)."""
        return self.sizers[self.sample_kind()]

    def sample_kind(self) -> str:
        """The kind of the sample's tiles: "tile" while the samples trace the gathers, then
        "lit tile": the later samples trace none (``preview.progressive.sample_settings``), so
        their tiles take a fraction of the time and are sized by a fit of their own."""
        return "tile" if self.sample < gather_samples(self.target) else "lit tile"

    def slice_pixels(self, explore: bool = True) -> int:
        """Pixels of the next slice (at most the image's); explore : as ``SliceSizer.pixels``'
        (False for the coarse image: the view waits for it, so never a larger size to
        measure)."""
        acc = self.accumulation
        most = acc.width * acc.height
        if self.fixed_pixels is not None:
            return max(1, min(most, self.fixed_pixels))
        return self.sizer.pixels(most, explore)

    def coarse_size(self, stride: int) -> tuple[int, int]:
        """The coarse image: the whole view at about one slice's pixels or, once a coarse image
        was measured, as many as its stages can trace within COARSE_WORK in all (the view waits
        for every one of them), with the view's aspect, at most about half its width and
        height; sides of the tiles' kind (``tile_side``: whole work groups, no power of two)."""
        acc = self.accumulation
        pixels = self.slice_pixels(explore=False)
        coarse = self.sizers["coarse"]
        if self.fixed_pixels is None and coarse.samples:
            # its own fit of its stages' whole time: a coarse image costs more a pixel than a
            # tile (its gathers all of a sample's rays); while one size was measured, that
            # size's seconds a pixel, its fixed cost included
            if coarse.model() is not None:
                fit = coarse.pixels(acc.width * acc.height, explore=False)
            else:
                measured, seconds = coarse.samples[-1]
                fit = max(coarse.least, int(COARSE_WORK * measured / max(seconds, 1e-6)))
            pixels = min(pixels, fit)
        # (a square tile stretched over the view, or half of both sides whatever the pixels,
        # before: a coarse image of 80 × 80 pixels became 160 × 90, twice its work); its sides
        # whole work groups of the gather grid as the tiles' (LOCAL_SIZE cells of stride
        # pixels): a side of another kind made llvmpipe build kernel variants mid-session
        # (a view change's first image 1.4 s with an empty shader cache)
        scale = min(0.5, math.sqrt(pixels / (acc.width * acc.height)))
        multiple = LOCAL_SIZE * stride
        return (max(1, min(acc.width, tile_side(acc.width * scale, multiple, stride))),
                max(1, min(acc.height, tile_side(acc.height * scale, multiple, stride))))

    def _next_tiles(self, stride: int) -> None:
        acc = self.accumulation
        # sides of whole work groups of the gather grid (LOCAL_SIZE cells of stride pixels)
        tile_w, tile_h = tile_shape(self.slice_pixels(), acc.width, acc.height,
                                    LOCAL_SIZE * stride, stride)
        # the grid moves by a hashed fraction of a tile each sample (whole GI blocks), along
        # the axes where tiles are smaller than the image
        k = self.sample
        shift = ((k * 5 % 8) * tile_w // 8 // stride * stride if tile_w < acc.width else 0,
                 (k * 3 % 8) * tile_h // 8 // stride * stride if tile_h < acc.height else 0)
        self.tiles = tile_grid(acc.width, acc.height, tile_w, tile_h, shift,
                               trim=lambda n: fit_side(n, LOCAL_SIZE * stride, stride))
        self.tile_count = len(self.tiles)
        self.tile_stride = stride

    def _split_next(self, kind: str) -> None:
        """Cut the next tile where the key's cost map predicts one of its stages past the
        stage budget (``preview.tile_costs.split_to_fit``): its parts go first. Not with
        whole slices a call, nor where a test fixed the slices' pixels."""
        if not self.tiles or self.stage_budget is None or self.costs is None or \
                self.fixed_pixels is not None:
            return
        stride = self.tile_stride
        parts = split_to_fit(self.tiles[0], lambda rect: self.costs.longest(kind, rect),
                             SPLIT_SHARE * self.stage_budget, LOCAL_SIZE * stride, stride,
                             self.costs.inside)
        if len(parts) > 1:
            self.tiles[0:1] = parts
            self.tile_count += len(parts) - 1

    # ------------------------------------------------------------------ tracing

    def step(self, trace, view, window, settings, filter_width: float,
             whole: bool = False, spent: float = 0.0) -> Slice | None:
        """Run the current key's slice on: its next stages while this call has spent less than
        ``stage_budget`` and the next stage — as long as it was in the last slice of this kind
        — would end within WORK_SHARE of the budget (all of them when ``stage_budget`` is
        None); ``trace(camera, width, height, options)`` → passes (PASS_NAMES → (h, w, 3)), or
        a generator of the tracer's stages returning them
        (``gpu_preview.render_passes_stages``). Returns the Slice when it finished in this
        call, a Slice with ``finished`` False while it goes on in the next call, None when the
        image has converged. whole: run the slice to its end. spent : seconds the draw has
        spent already (``viewport_prepare``'s steps): a first stage that took the last slice of
        its kind so long that the draw would end past the work share — or one never timed, past
        half of it — waits for the next draw.
        A stage that compiled a shader (``gpu_shaders.counters``: one the kernel warm-up had
        not) ends the draw's stages."""
        if self.converged or self.accumulation is None:
            return None
        staged = self.stage_budget is not None and not whole
        if self.skip_first and staged:
            self.skip_first = False  # (``restart``) the next draw of this key starts it
            return Slice("wait", (0, 0, 0, 0), (0, 0), self.sample, finished=False)
        t0 = time.perf_counter() - spent  # the draw's start
        kind = "coarse" if self.coarse_pending else self.sample_kind()
        if self.running is None and kind != "coarse":
            if not self.tiles:  # the sample's tiles, made here so the first is cut as the rest
                self._next_tiles(base_options(settings, self.accumulation.width,
                                              self.accumulation.height)["gi_stride"])
            self._split_next(kind)
        if self.running is not None:
            upcoming = self.predicted(kind, self.running_stage, self.running_pixels)
        else:
            upcoming = self.predicted(kind, 0, self.tiles[0][2] * self.tiles[0][3]
                                      if self.tiles and kind != "coarse" else 0)
        share = WORK_SHARE * max(self.budget, self.stage_budget or 0.0)
        if staged and spent > 0.0 and (spent + upcoming > share if upcoming is not None
                                       else spent > 0.5 * share):
            return Slice("stage", (0, 0, 0, 0), (0, 0), self.sample, finished=False)
        if self.running is None:
            self.running_kind = kind
            self.running = self._slice(trace, view, window, settings, filter_width)
            self.running_started, self.longest_stage, self.running_stage = \
                time.perf_counter(), 0.0, 0
            self.running_work = 0.0
        while True:
            s0 = time.perf_counter()
            compiles = counters.compiles
            try:
                next(self.running)
            except StopIteration as end:
                self.running = None
                done = end.value
                self.longest_stage = max(self.longest_stage, time.perf_counter() - s0)
                self.running_work += time.perf_counter() - s0
                done.seconds = time.perf_counter() - self.running_started
                # the sizer fits what one call costs: the slice, or its longest stage; the
                # coarse image's, what the view waits for: all its stages
                staged = self.stage_budget is not None
                sizer = self.sizers[self.running_kind]
                sizer.measured(done.size[0] * done.size[1],
                               self.running_work if self.running_kind == "coarse" else
                               self.longest_stage if staged else done.seconds)
                self.slices += 1
                self.elapsed = time.perf_counter() - self.started
                self.last = done
                return done
            except BaseException:
                self.running = None
                raise
            seconds = time.perf_counter() - s0
            self.longest_stage = max(self.longest_stage, seconds)
            self.running_work += seconds
            key = self.running_kind, self.running_stage
            self.stage_seconds[key] = [*self.stage_seconds.get(key, ()),
                                       (seconds, self.running_pixels)][-STAGE_HISTORY:]
            if self.running_rect is not None and self.costs is not None:
                self.costs.measured(key, self.running_rect, seconds)
            self.running_stage += 1
            if staged:
                # stop at the stage budget, or before a next stage that took the last slice of
                # this kind so long that this call would end past the work share of the budget,
                # or after a stage that compiled a kernel
                spent = time.perf_counter() - t0
                # a stage never timed (the first slice of its kind: entering Rendered mode)
                # is taken to be as long as the longest one timed, and at least half a
                # stage's budget (the first coarse image's later stages run 7–11 ms after
                # early ones of 1–4: two of them in a call made 21–27 ms)
                upcoming = self.predicted(self.running_kind, self.running_stage,
                                          self.running_pixels)
                if upcoming is None:
                    upcoming = max(max((t for times in self.stage_seconds.values()
                                        for t, _ in times), default=0.0),
                                   UNTIMED_SHARE * self.stage_budget)
                if spent >= self.stage_budget or counters.compiles != compiles or \
                        spent + upcoming > WORK_SHARE * max(self.budget, self.stage_budget):
                    return Slice("stage", (0, 0, 0, 0), (0, 0), self.sample, finished=False)

    def predicted(self, kind: str, index: int, pixels: int) -> float | None:
        """Seconds stage ``index`` of the next slice of ``kind`` (``pixels`` of it; 0:
        unknown) is taken to run: the longest of its last STAGE_HISTORY, each scaled up to
        ``pixels`` where it ran over fewer (never down: a stage's fixed cost stays); None
        when it never ran."""
        times = self.stage_seconds.get((kind, index))
        if not times:
            return None
        return max(t * max(1.0, pixels / p) if pixels and p else t for t, p in times)

    def _slice(self, trace, view, window, settings, filter_width: float):
        """The next slice — the coarse image or one tile — as a generator of stages: the
        tracer's, then adding it to the samples and the estimate; returns its Slice."""
        acc = self.accumulation
        width, height = acc.width, acc.height
        options = base_options(settings, width, height)

        def world(camera, w, h):  # the world along the slice's camera rays (the film's)
            return world_along(self.world, camera, w, h) if self.film else None

        def traced(camera, w, h, opts):
            result = trace(camera, w, h, opts)
            if inspect.isgenerator(result):
                result = yield from result
            return result

        if self.coarse_pending:
            size = self.coarse_size(options["gi_stride"])
            gather, lights = sample_settings(options["gather_settings"],
                                             options["light_samples"], self.target, 0,
                                             gathering=self.target)  # a quick image
            self.running_pixels = size[0] * size[1]
            self.running_rect = None
            camera = camera_from_view(view, window, *size)
            centre = self.coarse_centre(size) if self.coarse_centre is not None else None
            self.coarse_centre = None
            passes = yield from traced(camera, *size, {**options, "gather_settings": gather,
                                                      "light_samples": lights,
                                                      **self.coarse_options,
                                                      **({} if centre is None else
                                                         {"centre": centre})})
            yield  # the estimate is a stage of its own
            coarse = GPUAccumulation(acc.pass_name, *size, self.film, acc.transparent)
            coarse.add((0, 0, *size), passes, world=world(camera, *size))
            self.backdrop = coarse.estimate()
            # the image over it (the whole view's pixels) is a stage of its own: with the
            # add and the backdrop the coarse slice's last stage took 23–29 ms on the box
            # (docs/gi_pipeline.md "Entering Rendered mode")
            yield
            self.coarse_pending = False
            done = Slice("coarse", (0, 0, width, height), size, 0)
        else:
            if not self.tiles:
                self._next_tiles(options["gi_stride"])
            rect = self.tiles.pop(0)
            self.running_pixels = rect[2] * rect[3]
            self.running_rect = rect
            gather, lights = sample_settings(options["gather_settings"],
                                             options["light_samples"], self.target, self.sample)
            full = camera_from_view(view, window, width, height)
            offset = sample_offset(filter_width, self.target, self.sample)
            camera = tile_camera(full, *rect, offset=offset)
            # the sample's textures over its pixels' own squares, as F12's centre pass takes
            # them, not at its moved camera rays' points (docs/gi_pipeline.md "A sample's
            # textures over its pixel's square")
            tile_options = {**options, "gather_settings": gather, "light_samples": lights,
                            "texture_filter": (filter_width, (-offset[0], -offset[1]))}
            weight = 1.0
            if settings.quality == "ACCURATE":  # the filter runs on the accumulated gathers
                if self.gathers is None:
                    self.gathers = GPUGatherSums(width, height, options["gi_stride"])
                tile_options["gather_hook"] = gather_hook(self.gathers, rect, gather)
                # (not a view's only gathering sample: its converged image gathers densely)
                tile_options["lattice"] = LATTICE_FIRST and self.sample == 0 and \
                    gather_samples(self.target) > 1
                # the samples behind the tile's gathers; none after the gathering samples,
                # which add no gathered light (``sample_settings``)
                weight = float(self.sample + 1) if self.sample < gather_samples(self.target) \
                    else 0.0
            passes = yield from traced(camera, rect[2], rect[3], tile_options)
            yield  # the estimate is a stage of its own
            acc.add(rect, passes, gather_weight=weight,
                    tails=sample_tail_weights(filter_width, self.target, self.sample),
                    mean_tails=neighbour_weights(filter_width) if MEAN_TAILS else None,
                    world=world(camera, rect[2], rect[3]))
            done = Slice("tile", rect, (rect[2], rect[3]), self.sample)
            if not self.tiles:
                self.sample += 1
                self.converged = self.sample >= self.target
        if self.converged:  # every pixel has its samples: no backdrop
            self.image = acc.estimate()
        elif done.kind == "tile" and self.image is not None \
                and (self.image.width, self.image.height) == (width, height) \
                and not self.image_stale:
            acc.estimate_into(self.image, done.rect)  # only the tile's pixels changed
        else:  # the backdrop (scaled) where no tile landed yet
            self.image = acc.estimate(backdrop=self.backdrop)
        self.image_stale = False
        return done

    def read_image(self) -> np.ndarray | None:
        """(H, W, 4) float32 of the current estimate, row 0 on top: a read-back for tests and
        tools (the view draws the texture itself)."""
        return None if self.image is None else read_rgba(self.image)

    @property
    def samples_done(self) -> int:
        return self.sample

    def stage(self) -> str:
        """'Coarse image', 'Tile 3/12', 'Converged' (what the last slice did)."""
        if self.converged:
            return "Converged"
        if self.last is None or self.last.kind == "coarse":
            return "Coarse image"
        done = self.tile_count - len(self.tiles)
        return f"Tile {done}/{self.tile_count}"


def gather_hook(sums, rect, gather):
    """``render_passes_gpu``'s gather_hook for one tile: add the tile's raw gather to ``sums``
    (a ``gpu_gather_sums.GPUGatherSums``, on the GPU) and hand the filter the mean over all
    samples so far."""
    rays = {"diffuse": gather.rays, "glossy": gather.glossy_rays,
            "world glossy": gather.glossy_rays}

    def hook(kind, values, variance, lattice=False):
        # behind glass: its own sums, with the front's rays; lattice: the gather's lattice
        # only (the first sample's), spread over the grid with holes the filter fills
        return sums.add(kind, rect, values, variance, rays[kind.removeprefix("behind ")],
                        lattice=lattice)
    return hook


def tracer(live, volume, settings, staged: bool = False, raster=None, cache_source=None,
           batch=None):
    """``trace(camera, width, height, options)`` → passes: the GPU tracer on what ``live``
    has for the view (``LiveGI.image_source``: Accurate the latest snapshot, Fast the applied
    results) with F12's kernels (``render_passes_gpu``); staged: a generator of its stages that
    returns them (``render_passes_stages``, what ``ProgressiveImage.step`` runs over several
    calls; they return the pass's sums as textures where they can — Accurate, Fast with
    shadow rays, no glass: ``gpu_accumulation.GPUSums``, which ``GPUAccumulation.add`` takes
    as it takes passes).
    raster : the G-buffer shader the caller keeps for its GPU context; cache_source :
    the view's radiance cache built in stages (``viewport_cache.ViewportCache``); batch : the
    caller's vertex batch of the scene's triangles for ``raster`` (Accurate; None: one per
    slice)."""
    from .gpu_preview import render_passes_stages

    cones = cone_settings(settings)

    def stages(camera, width, height, options):
        snapshot, state, _ = live.image_source(settings.quality)
        snapshot = dataclasses.replace(snapshot, camera=camera)
        passes, _ = yield from render_passes_stages(snapshot, state, width, height,
                                                    cones, volume=volume, raster=raster,
                                                    cache_source=cache_source, on_gpu=staged,
                                                    batch=batch, **options)
        return passes

    def trace(camera, width, height, options):
        from .frame import finish
        return finish(stages(camera, width, height, options))
    return stages if staged else trace

"""Entering Rendered mode without a freeze: what the view's first GI image needs — the GPU
scene of the snapshot it traces, its vertex batch and the tracer's kernels — made ready a
bounded step per ``view_draw``, the CPU work on a thread of its own (docs/gi_pipeline.md
"Entering Rendered mode").

Blender runs every ``gpu`` call on the main thread inside ``view_draw``, so the GPU work is cut
into steps of which a draw takes at most one of each kind:

* **the scene** (``ScenePreparation``, one per process like the ``GPUScene`` it fills):
  ``GPUScene.prepare`` — world-space triangles, BVH build and packing, texture atlas, material,
  light, world and emitter tables — runs on the preparing thread (``PrepWorker``, beside the
  engine worker, so it never queues behind the session's update job) as soon as the session
  takes the snapshot (``prepare_snapshot``, called by ``LiveGI.schedule``), or at once when it
  is cheap (``GPUScene.cheap``: a lamp or a material changed, about a millisecond);
  ``GPUScene.upload_steps`` then sends one part per draw (the BVH's three textures one at a
  time) — the other parts, and the kernels of the scene's features, while the BVH still
  builds beside them (``GPUScene.prepare``'s on_tables hands the plan over before it);
* **the vertex batch** of the G-buffer raster (``ViewPreparation``, one per view, since a
  batch belongs to its GPU context): its attributes are made on the preparing thread with the
  scene (``gbuffer.vertex_arrays``) and sent a chunk of ``CHUNK_TRIANGLES`` triangles per draw
  — after an object moved, only the chunks whose attributes changed (``changed_chunks``)
  (``BatchFill``); the view's slices then draw it instead of making one per slice (250 ms a
  slice on a 140k-triangle scene), and only its chunks inside the slice's view
  (``gbuffer.ChunkedBatch``);
* **the kernels** (``kernel_steps``): every compute shader the view's slices use, in the
  order they first use them, compiled one per draw before they are needed — the ones of the
  coarse first image first, then the tiles' and the radiance cache's (those no scene's
  features choose are usually in already: ``kernel_warmup`` compiles them while the file is
  open);
* **a quick image**: once the raster shader and the batch are there, the view shows Solid-like
  shading of the G-buffer (``shaders/quick_shade.glsl``: Base Color under a headlight) until
  the first GI image replaces it, so the view is not empty while the BVH, the lights and the
  kernels come in; its G-buffer, at the first coarse image's size and camera and drawn by the
  batch's fill as each chunk is sent (``QuickGBuffer``), is that coarse image's
  (``ViewPreparation.coarse_centre``).

A draw runs a step only while it is predicted to end within ``STEP_SHARE`` of the slice
budget by the last time of a step of its kind (the first step of a draw always runs); the
view asks for redraws until its image has converged — except a draw that found nothing to
do but wait for the preparing thread: it asks for its redraw once that thread has moved on
(``wake_later``, a timer polling ``preparing_state``), so that the waiting view's redraws
(its last image drawn again, 5–10 ms of llvmpipe's cores each) do not starve the BVH build.
``gpu_shaders.counters`` counts the compiles and the scene parts sent, which the tests count
per draw.
"""
from __future__ import annotations

import contextlib
import dataclasses
import threading
import time

import bpy
import gpu
import numpy as np

from ..blender.jobs import background_priority
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.radiance_cache import snap_focus
from ..voxgi_addon.preview.gather import uses_cache
from ..voxgi_addon.scene.textures import TEXTURE_TAPS
from ..voxgi_addon.scene.view_camera import camera_from_view
from . import (
    gpu_accumulation,
    gpu_compose,
    gpu_gather,
    gpu_gather_sums,
    gpu_preview,  # noqa: F401 - imported with the view, not in its first slice
)
from .gbuffer import ChunkedBatch, gbuffer_shader, rasterize, vertex_arrays
from .gpu_bvh import EMITTERS_ONLY, absent_lights, bvh_features, bvh_shader, has_metals
from .gpu_scene import WAITING, current_scene
from .gpu_shaders import LOCAL_SIZE, build_compute, compute_shader, counters, note_upload
from .gpu_volume import float_texture
from .progressive import STAGE_SHARE, base_options

# of the budget: a draw starts no further step predicted to end past it (half: the draw's
# image costs 8–25 ms at the GPU's finish; docs/gi_pipeline.md "Entering Rendered mode")
STEP_SHARE = 0.5


# ---------------------------------------------------------------- the scene (preparing thread)

@dataclasses.dataclass
class VertexArrays:
    """The vertex attributes of a scene's triangles (``gbuffer.vertex_arrays``) and the
    materials' Base Colours (the quick image's palette), made on the preparing thread."""

    tris: object
    rough: np.ndarray
    textured: bool
    arrays: dict
    palette: np.ndarray
    # the chunks (``CHUNK_TRIANGLES``) whose attributes differ from the last arrays' (an object
    # moved: only its chunks are sent again); None: all of them
    changed: tuple | None = None
    chunk: int = 0  # the chunk size ``changed`` counts in

    def fits(self, scene) -> bool:
        """For the triangles, roughness table and texturing ``scene`` (a ``GPUScene``) has."""
        return (self.tris is scene.tris and scene.rough is not None
                and (self.rough is scene.rough or np.array_equal(self.rough, scene.rough))
                and self.textured == scene.textured)


def changed_chunks(known: VertexArrays | None, arrays: dict) -> tuple | None:
    """The indices of the ``CHUNK_TRIANGLES`` chunks of ``arrays`` whose attributes differ from
    ``known``'s (same triangle count), or None (all: nothing to compare with). Any thread."""
    if known is None or known.arrays is None or known.chunk != CHUNK_TRIANGLES or \
            len(known.arrays["position"]) != len(arrays["position"]) or \
            known.arrays.keys() != arrays.keys():
        return None
    corners = 3 * CHUNK_TRIANGLES
    count = -(-len(arrays["position"]) // corners)
    return tuple(k for k in range(count) if any(
        not np.array_equal(known.arrays[name][k * corners:(k + 1) * corners],
                           arrays[name][k * corners:(k + 1) * corners]) for name in arrays))


class PrepWorker:
    """The thread that prepares the view's GPU scenes (``ScenePreparation.request``): its own,
    beside the engine worker, so a new snapshot's scene is not queued behind the session's
    update job (a voxelization of seconds, or a superseded job still running to its next
    cancel check: an object move waited 0.4 s for it). Tasks run in the order they came, and
    one not started yet is replaced by a newer one of the same ``key``. In background mode
    (``jobs.runs_synchronously``: scripts, tests) a task runs at once on the calling thread."""

    def __init__(self):
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._tasks: dict = {}
        self._thread = None
        self._stop = False
        self._running = False

    @property
    def busy(self) -> bool:
        """A task runs or waits (what a bake on the main thread must wait for:
        ``bakes.busy_thread``)."""
        return self._running or bool(self._tasks)

    def submit(self, key: str, task) -> None:
        from ..blender import jobs

        if jobs.runs_synchronously():
            task()
            return
        with self._lock:
            self._tasks.pop(key, None)
            self._tasks[key] = task
            if self._thread is None or not self._thread.is_alive():
                self._stop = False
                self._thread = threading.Thread(target=self._run, name="VoxGI viewport scene",
                                                daemon=True)
                self._thread.voxgi_busy = lambda: self.busy
                self._thread.start()
        self._wake.set()

    def _run(self) -> None:
        background_priority()  # below the view's draws (its threads inherit it)
        while not self._stop:
            self._wake.wait()
            with self._lock:
                task = self._tasks.pop(next(iter(self._tasks))) if self._tasks else None
                if not self._tasks:
                    self._wake.clear()
                self._running = task is not None
            try:
                if task is not None and not self._stop:
                    task()
            finally:
                self._running = False

    def stop(self, timeout: float = 5.0) -> None:
        """End the thread (unregister, exit) after the task it is running."""
        thread = self._thread
        self._stop = True
        self._wake.set()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self._thread, self._tasks = None, {}


worker = PrepWorker()


class SceneJob:
    """The worker's preparation of one snapshot's GPU scene: its ``plan``
    (``GPUScene.prepare``) and its vertex ``arrays`` (set as soon as the triangles are known,
    before the BVH is built)."""

    def __init__(self, snapshot):
        self.snapshot = snapshot
        self.plan = None
        self.arrays: VertexArrays | None = None
        self.error = ""
        self.done = False
        self.started = time.perf_counter()
        self.seconds = 0.0
        self.finished = threading.Event()


class ScenePreparation:
    """The GPU scene of the snapshot the views trace, prepared on the preparing thread and
    uploaded a part per draw (module doc)."""

    def __init__(self):
        self.job: SceneJob | None = None  # the latest snapshot asked for
        self.steps = None                 # the upload of its plan, under way
        self.applied = None               # (snapshot, scene keys) of the last plan that went in
        self.arrays: VertexArrays | None = None  # of the latest triangles
        self.sent = 0                     # parts sent of the upload under way (status)
        # (live GI, snapshot, version): the snapshot the views finish preparing and show
        # before a newer one (a playing rig's frames: ``hold_source``), None when none is held
        self.hold = None

    def request(self, scene_name: str, snapshot) -> SceneJob:
        """Prepare ``snapshot``'s scene (``PrepWorker``) unless it is being or has been."""
        job = self.job
        if job is not None and job.snapshot is snapshot and not job.error:
            return job
        job = self.job = SceneJob(snapshot)
        self.steps, self.sent = None, 0
        scene = current_scene()
        known = self.arrays

        def geometry(tris, rough, textured, principled):
            # the quick image's and the batch's attributes, before the BVH is built
            palette = np.asarray(principled[0])
            if known is not None and known.tris is tris and known.textured == textured \
                    and np.array_equal(known.rough, rough):
                arrays = known if np.array_equal(known.palette, palette) else \
                    dataclasses.replace(known, palette=palette, changed=())
            else:
                made = vertex_arrays(tris, rough, textured)
                arrays = VertexArrays(tris, rough, textured, made, palette,
                                      changed_chunks(known, made), CHUNK_TRIANGLES)
            job.arrays = arrays
            if self.job is job:
                self.arrays = arrays

        def tables(plan):
            # every part but the BVH (built meanwhile): the view sends them and compiles the
            # kernels of the scene's features while it builds
            job.plan = plan
            # the triangles' bounds, which every slice's radiance-cache focus reads
            # (``preview.gather.focused``; kept per positions array): 24–33 ms over the
            # diorama's 142k triangles, which the first slice stage of each new scene paid
            if len(getattr(plan.tris, "positions", ())):
                snap_focus(plan.tris, np.zeros(3))

        def run():  # the preparing thread: numpy on the snapshot and the scene's keys only
            try:
                if self.job is job:  # (else a newer snapshot came first)
                    job.plan = scene.prepare(snapshot, on_geometry=geometry, on_tables=tables)
                else:
                    job.error = "superseded"
            except VoxGIError as error:
                job.error = str(error)
            except Exception as error:  # noqa: BLE001 - the view says why and keeps drawing
                job.error = f"{type(error).__name__}: {error}"
            job.seconds = time.perf_counter() - job.started
            job.done = True  # the view, asking for redraws meanwhile, picks it up
            job.finished.set()

        if scene.cheap(snapshot):  # a lamp, a material: a millisecond, no worker round trip
            run()
        else:
            worker.submit("scene", run)
        return job

    def ready(self, snapshot) -> bool:
        """The current ``GPUScene`` is ``snapshot``'s (its plan went in, nothing since)."""
        return self.applied is not None and self.applied[0] is snapshot \
            and current_scene().keys == self.applied[1]

    def upload_step(self, snapshot) -> str:
        """One step of sending ``snapshot``'s prepared scene: "" when there was nothing to do
        (not prepared yet, or in already), else what it did ("uploaded", "applied": the last
        step, or "stale": prepared against another state of the scene — or the same content
        from other triangles than the vertex arrays were made of — asked again)."""
        job = self.job
        # the plan is there before the BVH is built (``GPUScene.prepare``'s on_tables): its
        # other parts go in meanwhile
        if job is None or job.snapshot is not snapshot or job.plan is None or job.error:
            return ""
        scene = current_scene()
        if self.steps is None:
            if self.ready(snapshot):
                return ""
            self.steps, self.sent = scene.upload_steps(job.plan), 0
        try:
            if next(self.steps) == WAITING:
                return ""  # the BVH is still building: nothing sent
            self.sent += 1
            return "uploaded"
        except StopIteration:
            self.steps = None
        if scene.keys == job.plan.keys and scene.tris is job.plan.tris:
            self.applied = (snapshot, dict(scene.keys))
            return "applied"
        # prepared against another state (F12 or another render updated the scene first):
        # again, against this one (nothing of it is sent again that it already has)
        self.job = None
        self.applied = None
        return "stale"

    @property
    def total(self) -> int:
        job = self.job
        return 0 if job is None or job.plan is None else job.plan.parts

    def free(self) -> None:
        if self.steps is not None:
            self.steps.close()
        self.__init__()


preparation = ScenePreparation()

WAKE_POLL = 0.01   # seconds between a waiting view's checks of the preparing thread
WAKE_MOST = 0.25   # a waiting view is drawn again after this at the latest
_waiting: list[tuple[object, object, float]] = []  # (redraw, state waited on, deadline)


def preparing_state():
    """What the preparing thread has handed over so far: a draw can do more only once this
    changes (the vertex arrays, the scene's tables, the BVH built, the job done)."""
    job = preparation.job
    if job is None:
        return None
    plan = job.plan
    return (id(job), job.arrays is not None, plan is not None,
            plan is not None and plan.bvh_ready.is_set(), job.done)


def wake_later(redraw) -> None:
    """Call ``redraw`` (a view's redraw request) once ``preparing_state`` changes, or after
    ``WAKE_MOST``: from a ``bpy.app.timers`` callback in Blender's UI; without an event loop
    (the benchmark) its caller runs ``wake_tick`` as the timer would."""
    _waiting.append((redraw, preparing_state(), time.perf_counter() + WAKE_MOST))
    # (timers never fire without an event loop, and one left registered at a background
    # process's exit crashed it)
    if not bpy.app.background and not bpy.app.timers.is_registered(wake_tick):
        bpy.app.timers.register(wake_tick, first_interval=WAKE_POLL)


def wake_tick() -> float | None:
    """The waiting views' timer: asks for the redraws whose wait is over; the next check's
    delay, or None when no view waits."""
    state, now = preparing_state(), time.perf_counter()
    waiting = []
    for entry in _waiting:
        redraw, seen, deadline = entry
        if state == seen and now < deadline:
            waiting.append(entry)
            continue
        with contextlib.suppress(ReferenceError):  # the view's engine freed meanwhile
            redraw()
    _waiting[:] = waiting
    return WAKE_POLL if waiting else None


def prepare_snapshot(live, snapshot, scene):
    """``LiveGI``'s hook for a new snapshot (``viewport_session.SNAPSHOT_HOOKS``): in Accurate
    quality the view traces that very snapshot, so its GPU scene is prepared at once; the
    session's update job (voxels for Fast, F12 and the panels) waits for it (the event
    returned), so the two do not share the 2 cores while the user waits for the image."""
    if scene is not None and getattr(scene.voxgi, "quality", "") == "ACCURATE":
        held = preparation.hold
        if held is not None and held[0] is live and held[1] is not snapshot:
            return None  # the view finishes the frame it prepares first (``hold_source``)
        return preparation.request(live.scene_name, snapshot).finished
    return None


def hold_source(live, source, shown_version):
    """The (snapshot, state, version) an Accurate view traces: ``source`` (``LiveGI.
    image_source``: the latest snapshot), unless the view is still preparing an earlier one
    that it has shown nothing of yet — then that one, finished first. A new snapshot
    superseded the one being prepared, so while a rig played (a snapshot a frame, each ~130 ms
    from its GPU scene to its first image on the rig room) no frame's own image was ever drawn;
    now the view shows one frame after another as fast as they can be prepared, the newest
    next, and drops the ones between (docs/gi_pipeline.md "Posed updates"). shown_version :
    the version of the image the view shows."""
    held = preparation.hold
    job = preparation.job
    if held is not None and (held[0] is not live or shown_version == held[2] or (
            job is not None and job.snapshot is held[1] and job.error)):
        preparation.hold = held = None  # its image is drawn (or it failed): the newest next
    if held is not None and held[2] != source[2]:
        return held[1], source[1], held[2]
    return source


def hold_traced(live, source, traced_version, shown_version) -> None:
    """After a draw that traced ``source``'s image (``traced_version``: its key's version):
    hold it while the view has shown nothing of it (``hold_source``)."""
    if source is not None and traced_version == source[2] and traced_version != shown_version:
        preparation.hold = (live, source[0], source[2])


# ---------------------------------------------------------------- the kernels

@dataclasses.dataclass(frozen=True)
class Features:
    """What picks the kernels' variants (``gpu_bvh.bvh_shader``) and which the view needs:
    some cut-out, some triangle hidden from a kind of ray, textured hits, the kinds of light
    the scene has none of (every light's dispatch takes that one variant), some lamp (or a
    world map's sun, traced as one), some light of the world or the emitters, some emissive
    triangle."""

    cutouts: bool
    hidden: bool
    textured: bool
    absent: tuple
    lamps: bool
    tail: bool
    emitters: bool
    direct_absent: tuple  # the direct-light dispatches' (``absent_lights``' direct)


def features(tris, lights, lamp_count: int, principled=None) -> Features:
    """The ``Features`` of a prepared scene: its triangles, lights list (lamps first) and
    Principled table (``passes.principled_table``; None: unknown)."""
    cutouts, hidden = bvh_features(tris)
    # a map's sun is traced as a lamp for the pixels' glossy lobes (world_light.sun_lamp)
    map_sun = any(getattr(light, "sun", None) is not None for light in lights)
    metals = has_metals(principled, tris)
    return Features(cutouts, hidden, getattr(tris, "textures", None) is not None,
                    absent_lights(lights, metals), lamp_count > 0 or map_sun,
                    len(lights) > lamp_count, any(light.type == "EMITTERS" for light in lights),
                    absent_lights(lights, metals, direct=True))


_QUICK: dict[str, object] = {}
QUICK_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "gbuffer_view", "palette")


def quick_shader():
    """The quick image's kernel (``shaders/quick_shade.glsl``), built once per process."""
    if "shader" not in _QUICK:
        _QUICK["shader"] = build_compute(("quick_shade",), QUICK_SAMPLERS, ("world",),
                                         name="quick shade")
    return _QUICK["shader"]


def kernel_steps(found: Features | None, quality: str, bounces: int, glossy_indirect: bool,
                 shadows: str = "RAYS") -> list[tuple[str, int, object]]:
    """(name, phase, getter) of every kernel the view's slices use, in the order they first
    use them: phase 1 the coarse first image's, phase 2 the tiles' and the radiance cache's
    (bounces > 1). The getters are the tracer's own cached ones, so a kernel compiled here is
    the one the slice binds. found : the scene's ``Features`` (None while the scene is being
    prepared: only the kernels every scene uses)."""
    steps: list[tuple[str, int, object]] = []

    def add(name, phase, getter):
        for index, (known, was, _) in enumerate(steps):
            if name == known:  # listed already: compiled by the earlier of the two phases
                steps[index] = (name, min(was, phase), getter)
                return
        steps.append((name, phase, getter))

    def bvh(kernel, phase, textures=None, absent=None):
        if found is None:
            return
        textures = found.textured if textures is None else textures
        absent = found.absent if absent is None else tuple(absent)
        add(f"{kernel} {int(found.cutouts)}{int(textures)}{int(found.hidden)} "
            f"{'-'.join(absent) or 'all'}", phase,
            lambda: bvh_shader(kernel, found.cutouts, textures, absent, found.hidden))

    add("quick shade", 1, quick_shader)
    if quality == "ACCURATE":
        bvh("bvh_gather", 1)
        # the first coarse image takes its gathers raw (``first_image_options``)
        add("denoise", 2, gpu_gather._denoise_shader)
        # the first sample's gather at the lattice: its holes filled (render/progressive.py
        # LATTICE_FIRST)
        add("denoise holes", 2, lambda: gpu_gather._denoise_shader(True))
        # ... and goes without the glossy indirect gather: its kernels come in phase 2
        if glossy_indirect:
            bvh("bvh_glossy", 2)
            add("upsample pair", 2, lambda: gpu_gather._upsample_shader(True))
        add("upsample", 1, lambda: gpu_gather._upsample_shader(False))
        if found is not None and found.tail:
            # the world's and emitters' Glossy Direct gather: not in the first coarse image
            # either (``first_image_options``)
            bvh("bvh_glossy", 2)
        if found is not None and found.emitters:
            bvh("bvh_emitter_glossy", 1, True, EMITTERS_ONLY)
            # the field's unshadowed sums: the direct dispatches' variant
            bvh("bvh_direct", 1, True, found.direct_absent)
            add("upsample field", 1, lambda: gpu_gather._field_shader(False))
    else:
        add("cone diffuse_ao", 1, lambda: compute_shader("diffuse_ao"))
        if glossy_indirect:
            add("cone glossy", 1, lambda: compute_shader("glossy"))
        add("cone upsample", 1, lambda: compute_shader("upsample"))
        if shadows != "RAYS":
            add("cone shadow", 1, lambda: compute_shader("shadow"))
    if quality == "ACCURATE" or shadows == "RAYS":  # gpu_compose.shade_stages
        add("aa_surface", 1, lambda: gpu_compose._aa_shader("aa_surface"))
        if found is not None and (found.lamps or found.tail):
            # every light's dispatch: the direct dispatches' one variant
            bvh("bvh_direct", 1, True, found.direct_absent)
        if found is not None and found.lamps:
            # the lamps' glossy light: not in the first coarse image (``first_image_options``)
            add("glossy direct", 2 if quality == "ACCURATE" else 1, gpu_gather._glossy_shader)
        add("aa_light", 1, lambda: gpu_compose._aa_shader("aa_light"))
    for name in ("pass_sample", "accumulate", "estimate"):
        add(name, 1, lambda name=name: gpu_accumulation._shader(name))
    if quality == "ACCURATE":
        add("gather sums", 2, gpu_gather_sums._shader)
    if bounces > 1:
        bvh("bvh_cache_paths", 2)
        add("cache relax", 2, gpu_gather._relax_shader)
    return steps


def kernel_key(found: Features | None, settings) -> tuple:
    """``kernel_steps``' arguments for a scene's ``Features`` and its VoxGI settings."""
    options = base_options(settings, 8, 8)
    gathers = options["gather_settings"]
    # (one bounce with glossy chains builds a cache too: its kernels as at two)
    bounces = max(gathers.bounces, 2) if uses_cache(gathers) else gathers.bounces
    return (found, settings.quality, bounces, options["glossy_indirect"], options["shadows"])


class KernelWarmup:
    """Compiles ``kernel_steps`` one per call (``step``), remembering which lists are done."""

    def __init__(self):
        self.done: set = set()
        self.count = (0, 0)  # (compiled or found so far, kernels) of the last list: status

    def pending(self, key, steps, phase: int) -> bool:
        return (key, phase) not in self.done and any(p <= phase for _, p, _ in steps)

    def step(self, key, steps, phase: int) -> str:
        """Compile the first kernel of ``steps`` up to ``phase`` that is not compiled yet:
        its name, or "" when every one is (the list is then remembered as done)."""
        if (key, phase) in self.done:
            return ""
        wanted = [s for s in steps if s[1] <= phase]
        for index, (name, _, getter) in enumerate(wanted):
            before = counters.compiles
            getter()
            if counters.compiles != before:
                self.count = (index + 1, len(wanted))
                return name
        self.count = (len(wanted), len(wanted))
        self.done.add((key, phase))
        return ""


warmup = KernelWarmup()


# ---------------------------------------------------------------- one view

def _batch_format(shader, arrays):
    """``gpu_extras.batch.batch_for_shader``'s vertex format for ``shader`` and ``arrays``
    (float attributes, as the raster's are)."""
    vbo_format = gpu.types.GPUVertFormat()
    for name, attr_type in shader.attrs_info_get():
        data = arrays[name]
        length = 1 if data.ndim == 1 else int(np.prod(data.shape[1:]))
        if attr_type in ("FLOAT", "VEC2", "VEC3", "VEC4", "MAT3", "MAT4"):
            vbo_format.attr_add(id=name, comp_type="F32", len=length, fetch_mode="FLOAT")
        else:
            vbo_format.attr_add(id=name, comp_type="I32", len=length, fetch_mode="INT")
    return vbo_format


CHUNK_TRIANGLES = 8192  # triangles per chunk of the view's batch (3 MB of attributes)
_ATTR_LENGTHS = {"FLOAT": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "INT": 1, "IVEC2": 2,
                 "IVEC3": 3, "IVEC4": 4}


# the camera of the warm-up draws into 8 × 8 G-buffers when the scene has none
WARM_CAMERA = camera_from_view(np.eye(4), np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0],
                                                    [0, 0, -1.0002, -0.020002], [0, 0, -1.0, 0]]),
                               8, 8, name="warm-up")


def warm_raster(shader, camera) -> None:
    """Draw one triangle of zeros with the raster ``shader`` into an 8 × 8 G-buffer: llvmpipe
    builds a shader's draw variant (its vertex fetch and fragment code) at its first draw,
    20–30 ms on the 2 cores, which made the batch's first chunk the longest step of the
    diorama's entering (37–44 ms against 10–14 ms for the others; docs/gi_pipeline.md
    "Entering Rendered mode"). A step of its own, made while the scene is prepared."""
    arrays = {}
    for name, attr_type in shader.attrs_info_get():
        length = _ATTR_LENGTHS.get(attr_type, 4)
        dtype = np.int32 if attr_type.startswith(("INT", "IVEC")) else np.float32
        arrays[name] = np.zeros(3 if length == 1 else (3, length), dtype)
    vbo = gpu.types.GPUVertBuf(_batch_format(shader, arrays), 3)
    for name, values in arrays.items():
        vbo.attr_fill(name, values)
    batch = gpu.types.GPUBatch(type="TRIS", buf=vbo)
    origin = np.zeros(3, np.float32)
    rasterize([None], camera, np.zeros(1, np.float32), 8, 8, shader=shader,
              batch=ChunkedBatch([batch], [(origin, origin)]))


def _same(a, b) -> bool:
    """Raster textures (None or a (table, atlas) pair of GPU textures) that are the same."""
    if a is None or b is None:
        return a is b
    return all(x is y for x, y in zip(a, b))


@dataclasses.dataclass
class QuickView:
    """What the view asks of the quick image: its image ``key``, the first coarse image's
    ``size`` and ``camera`` (the quick image's G-buffer is that coarse image's: drawn once,
    shaded for the quick image, then handed to the coarse slice, ``coarse_centre``), its
    Filter Size (the slices' G-buffers'), Film › Transparent, and ``show(texture)``."""

    key: object
    size: tuple
    camera: object
    filter_width: float
    transparent: bool
    show: object


@dataclasses.dataclass
class QuickGBuffer:
    """The quick image's G-buffer (``QuickView``'s size and camera) of ``source``'s batch
    with the scene's raster ``textures``: its chunks drawn into it in order, ``drawn`` of them
    so far — by the batch's fill as each chunk is sent (``BatchFill.step``), the rest by
    ``ViewPreparation.quick_step``."""

    key: object
    size: tuple
    camera: object
    filter_width: float
    source: VertexArrays
    textures: tuple | None
    gbuffer: object = None
    drawn: int = 0

    def matches(self, view: QuickView, source: VertexArrays, textures) -> bool:
        return self.key == view.key and self.size == view.size and self.source is source \
            and self.filter_width == view.filter_width and _same(self.textures, textures)

    def draw(self, shader, chunk: ChunkedBatch) -> None:
        """Draw the next chunk (``chunk``: one batch) into the G-buffer, as the coarse
        slice's visibility stage draws it (``gpu_preview._visibility``)."""
        self.gbuffer = rasterize(self.source.tris, self.camera, self.source.rough, *self.size,
                                 shader=shader, textures=self.textures,
                                 filter_width=self.filter_width, batch=chunk,
                                 out=self.gbuffer, texture_taps=TEXTURE_TAPS)
        self.drawn += 1


class BatchFill:
    """The view's vertex batch of ``VertexArrays`` for a raster shader as a
    ``gbuffer.ChunkedBatch`` of ``CHUNK_TRIANGLES`` triangles a chunk, made a chunk per
    ``step``: its attributes filled into its vertex buffer and the chunk drawn once into an
    8 × 8 G-buffer, which sends the buffer to the GPU (the first draw of a 140k-triangle
    batch in one piece took 0.48 s)."""

    def __init__(self, shader, source: VertexArrays, previous: ChunkedBatch | None = None):
        self.shader, self.source = shader, source
        self.names = [name for name, _ in shader.attrs_info_get()]
        self.format = _batch_format(shader, source.arrays)
        self.count = len(source.arrays["position"]) // 3  # triangles
        self.chunks = -(-self.count // CHUNK_TRIANGLES)
        self.filled = 0
        self.made = ChunkedBatch()
        self.batch = None  # the ChunkedBatch once every chunk is in
        # the previous batch's chunks whose attributes are unchanged (an object moved)
        self.kept = {}
        if previous is not None and source.changed is not None and \
                source.chunk == CHUNK_TRIANGLES and len(previous.batches) == self.chunks:
            self.kept = {k: (previous.batches[k], previous.bounds[k])
                         for k in range(self.chunks) if k not in source.changed}
        self._keep()

    def _keep(self) -> None:
        """Take the kept chunks up to the next one to send."""
        while self.filled < self.chunks and self.filled in self.kept:
            batch, bounds = self.kept[self.filled]
            self.made.batches.append(batch)
            self.made.bounds.append(bounds)
            self.filled += 1
        if self.filled == self.chunks:
            self.batch = self.made

    def step(self, camera, target: QuickGBuffer | None = None) -> None:
        """Send the next chunk. target : the quick image's G-buffer under way
        (``QuickGBuffer``): when every chunk before this one is in it, the chunk is drawn
        there (its first draw, which sends its vertices, and the quick image's share of it in
        one); else into an 8 × 8 G-buffer."""
        if self.batch is not None:
            return
        first = self.filled * CHUNK_TRIANGLES
        last = min(self.count, first + CHUNK_TRIANGLES)
        corners = slice(3 * first, 3 * last)
        note_upload(f"vertex batch {self.filled + 1}/{self.chunks}")
        vbo = gpu.types.GPUVertBuf(self.format, 3 * (last - first))
        for name in self.names:
            vbo.attr_fill(name, np.ascontiguousarray(self.source.arrays[name][corners],
                                                     np.float32))
        batch = gpu.types.GPUBatch(type="TRIS", buf=vbo)
        positions = self.source.arrays["position"][corners]
        chunk = ChunkedBatch([batch], [(positions.min(axis=0), positions.max(axis=0))])
        # drawn once, in full: its vertices go to the GPU now, not in a slice's G-buffer
        if target is not None and target.drawn == self.filled:
            target.draw(self.shader, chunk)
        else:
            rasterize(self.source.tris, camera, self.source.rough, 8, 8, shader=self.shader,
                      batch=chunk.batches[0])
        self.made.batches += chunk.batches
        self.made.bounds += chunk.bounds
        self.filled += 1
        self._keep()


class ViewPreparation:
    """One view's part (module doc): its raster shader, its vertex batch filled an attribute
    per draw, the quick image, the per-kind step times that predict whether a step fits."""

    def __init__(self):
        self.raster = None       # the G-buffer shader of this view's GPU context
        self.warmed = False      # the raster's first draw made (``warm_raster``)
        self.fill: BatchFill | None = None
        self.batch = None        # the filled batch and the VertexArrays it holds
        self.batch_source: VertexArrays | None = None
        self.quick: QuickGBuffer | None = None  # the quick image's G-buffer under way
        self.coarse: QuickGBuffer | None = None  # ... complete, for the first coarse image
        self.seconds: dict[str, float] = {}  # the last step of each kind
        self.timings: dict[str, float] = {}  # this draw's steps
        self.status = ""

    def free(self) -> None:
        self.__init__()

    def _fits(self, kind: str, started: float, budget: float) -> bool:
        """Whether a step of ``kind`` is predicted to end within ``STEP_SHARE`` of the budget
        by the last one's time; one never timed yet only in the first half of that. The draw's
        first step always runs."""
        spent = time.perf_counter() - started
        if spent == 0.0 or not self.timings:
            return True
        last = self.seconds.get(kind)
        if last is None:
            return spent <= 0.5 * STEP_SHARE * budget
        return spent + last <= STEP_SHARE * budget

    def _timed(self, kind: str, label: str, fn):
        t0 = time.perf_counter()
        value = fn()
        seconds = time.perf_counter() - t0
        self.seconds[kind] = seconds
        self.timings[label] = self.timings.get(label, 0.0) + seconds
        return value

    def batch_for(self, scene):
        """The filled batch when it is of ``scene``'s triangles, else None."""
        if self.batch is not None and self.batch_source.fits(scene):
            return self.batch
        return None

    def advance(self, scene_name: str, snapshot, settings, budget: float, started: float,
                quick=None, whole: bool = False) -> bool:
        """This draw's steps toward the first GI image of ``snapshot``: at most one scene part
        or batch attribute sent and one kernel compiled, each while it fits the budget
        (``STEP_SHARE``), then the quick image (``quick``: a ``QuickView`` when the view shows
        none yet for its key) when its parts are there. True when the view can
        trace: the scene is ``snapshot``'s, the batch its triangles' and the first image's
        kernels are compiled. whole : every step at once (no budget: the tests' whole slices,
        ``ProgressiveImage.stage_budget`` None)."""
        self.timings = {}
        while True:
            ready, worked = self._pass(scene_name, snapshot, settings, budget, started,
                                       None if whole else quick, whole)
            if ready or not whole or not worked:
                return ready

    def _pass(self, scene_name, snapshot, settings, budget, started, quick, whole):
        prep = preparation
        job = prep.request(scene_name, snapshot)
        if whole and not job.done:
            job.finished.wait(600.0)  # no budget: everything now, the worker's part included
        if job.error:
            raise VoxGIError(job.error)
        gpu_scene = current_scene()
        scene_ready = prep.ready(snapshot)
        arrays = job.arrays if job.arrays is not None else \
            (prep.arrays if scene_ready else None)
        worked = False
        # what the 8 × 8 warm-up draws look through: the scene's camera, or any (a free view
        # of a scene without one: its snapshot has none)
        camera = snapshot.camera if snapshot.camera is not None else WARM_CAMERA
        # one compile: the raster shader, then the kernels in their order
        compiled = ""
        if self.raster is None:
            self.raster = self._timed("compile", "compile gbuffer raster", gbuffer_shader)
            compiled, worked = "gbuffer raster", True
        found = None
        if job.plan is not None:
            found = features(job.plan.tris, job.plan.lights, len(snapshot.lights), job.plan.principled)
        key = kernel_key(found, settings)
        steps = kernel_steps(*key)
        if not compiled and (whole or self._fits("compile", started, budget)):
            t0 = time.perf_counter()
            compiled = warmup.step(key if found is not None else None, steps, 1)
            if compiled:
                seconds = time.perf_counter() - t0
                self.seconds["compile"] = seconds
                self.timings[f"compile {compiled}"] = seconds
                worked = True
        # the quick image's G-buffer (the first coarse image's, ``QuickView``): drawn with the
        # scene's raster textures, so a textured scene's fill waits for them (its first parts)
        known, textures = self._raster_textures(job, arrays, scene_ready)
        target = None
        if quick is not None and arrays is not None and known:
            if self.quick is None or not self.quick.matches(quick, arrays, textures):
                self.quick = QuickGBuffer(quick.key, quick.size, quick.camera,
                                          quick.filter_width, arrays, textures)
            target = self.quick
        # one upload: the raster's first draw (with a scene part: it sends nothing), else the
        # batch's next chunk, else the scene's next part
        sent = False
        if not self.warmed:  # (nothing drawn with the raster before it: its first draw)
            if compiled != "gbuffer raster" and (whole or self._fits("warm", started, budget)):
                self._timed("warm", "raster first draw", lambda: warm_raster(self.raster,
                                                                            camera))
                self.warmed = worked = True
        elif arrays is not None and (self.batch_source is not arrays or self.batch is None) \
                and not (quick is not None and not known):
            if self.fill is None or self.fill.source is not arrays:
                self.fill = None
                if len(arrays.tris):
                    self.fill = BatchFill(self.raster, arrays, self.batch)
            if self.fill is not None and self.fill.batch is None and \
                    (whole or self._fits("batch", started, budget)):
                self._timed("batch", "vertex batch",
                            lambda: self.fill.step(camera, target))
                worked = sent = True
            if self.fill is not None and self.fill.batch is not None:
                self.batch, self.batch_source, self.fill = self.fill.batch, arrays, None
        if not sent and not scene_ready and (whole or self._fits("upload", started, budget)):
            t0 = time.perf_counter()
            done = prep.upload_step(snapshot)
            if done:
                seconds = time.perf_counter() - t0
                self.seconds["upload"] = seconds
                self.timings[f"scene {done}"] = self.timings.get(f"scene {done}", 0.0) + seconds
                worked = True
            scene_ready = prep.ready(snapshot)
        # Accurate's slices draw the view's batch (Fast's make their own): the triangles' one
        batch = settings.quality != "ACCURATE" or self.batch_for(gpu_scene) is not None or \
            (scene_ready and not len(gpu_scene.tris))
        ready = scene_ready and batch and found is not None and \
            not warmup.pending(key, steps, 1)
        if not ready and target is not None and self.batch is not None \
                and self.batch_source is arrays and "shader" in _QUICK \
                and self._fits("quick chunk", started, budget):
            self._timed("quick", "quick image",
                        lambda: self.quick_step(quick, snapshot, budget, started))
        done, total = warmup.count
        parts = f"scene part {prep.sent}/{prep.total}" if job.plan is not None else \
            "preparing the scene"
        self.status = (f"Preparing: kernel {done}/{total} | {parts}"
                       + ("" if self.batch_source is arrays else " | vertex batch"))
        if not whole and not job.done:
            worked = False
        return ready, worked

    @staticmethod
    def _raster_textures(job, arrays, scene_ready: bool):
        """(known, textures): the raster textures (``GPUScene.raster_textures``) the scene of
        ``arrays``' triangles will have — None when they are untextured — once they are on
        the GPU (the plan's texture parts sent: ``ScenePlan.textures_sent``)."""
        if arrays is None:
            return False, None
        if not arrays.textured:
            return True, None
        plan = job.plan if job is not None else None
        if scene_ready or plan is None and current_scene().tris is arrays.tris:
            return True, current_scene().raster_textures()
        if plan is None:
            return False, None
        sent = plan.textures_sent
        if sent is None and plan.textures is None and plan.atlas is None and \
                plan.texture_table is None:
            sent = current_scene().textures  # the plan sends none: the scene's are its
        if sent is None or "texture_atlas" not in sent:
            return False, None
        return True, (sent["texture_table"], sent["texture_atlas"])

    def coarse_centre(self, key, size, scene, raster):
        """The quick image's G-buffer for the first coarse image of ``key`` at ``size`` (the
        same camera, batch and textures as its own visibility stage would draw: it is not
        drawn again; docs/gi_pipeline.md "Entering Rendered mode"), once, or None."""
        made, self.coarse = self.coarse, None
        if made is None or made.key != key or made.size != size or raster is not self.raster \
                or not made.source.fits(scene) or \
                not _same(made.textures, scene.raster_textures()):
            return None
        return made.gbuffer

    def first_image_options(self, snapshot, settings) -> dict:
        """The tracer's options that the coarse image overrides while the tiles' kernels
        (phase 2 of ``kernel_steps``) are not all compiled: the first GI image after entering
        Rendered mode is a minimal frame — the G-buffer, the diffuse gather unfiltered and
        upsampled, each light's direct light, composed — without the glossy indirect gather,
        the world's and emitters' Glossy Direct gather (their ``bvh_glossy`` variants and the
        paired upsample: compiles of 10–30 ms, 0.3 s with Mesa's cache cold, and a slice stage
        each), the lamps' glossy light (``glossy direct``) and the gathers' filter
        (``denoise``): fewer kernels, one compile per draw, before it (docs/gi_pipeline.md
        "Entering Rendered mode"); {} once they are. The tiles trace with all of them."""
        job = preparation.job
        if settings.quality != "ACCURATE" or job is None or job.plan is None:
            return {}
        found = features(job.plan.tris, job.plan.lights, len(snapshot.lights), job.plan.principled)
        key = kernel_key(found, settings)
        if not warmup.pending(key, kernel_steps(*key), 2):
            return {}
        options = {"denoise": False}
        if key[3]:
            options["glossy_indirect"] = False
        if found.tail:
            options["world_glossy"] = False
        if found.lamps:
            options["lamp_glossy"] = False
        return options

    def later_kernels(self, snapshot, settings, budget: float, started: float,
                      whole: bool = False) -> str:
        """Phase 2 (the tiles' and the radiance cache's kernels): compile the next one if it
        fits; its name, or "" when none was compiled."""
        job = preparation.job
        if job is None or job.plan is None:
            return ""
        key = kernel_key(features(job.plan.tris, job.plan.lights, len(snapshot.lights), job.plan.principled),
                         settings)
        steps = kernel_steps(*key)
        if not warmup.pending(key, steps, 2) or \
                not (whole or self._fits("compile", started, budget)):
            return ""
        t0 = time.perf_counter()
        name = warmup.step(key, steps, 2)
        if name:
            self.seconds["compile"] = time.perf_counter() - t0
            self.timings[f"compile {name}"] = self.seconds["compile"]
        return name

    def quick_step(self, view: QuickView, snapshot, budget: float, started: float) -> None:
        """The quick image (module doc) of ``view``: the chunks of the batch the fill did not
        draw into its G-buffer (``QuickGBuffer``) drawn a part per call while they fit
        ``STAGE_SHARE`` of the budget, as a slice's stages (their raster work ends at the
        draw's GPU finish, after the draw's Python: at ``STEP_SHARE`` the diorama's
        quick-image draws took 35 ms), then shaded and shown (``view.show``); its G-buffer is
        kept for the first coarse image (``coarse_centre``)."""
        state, batch = self.quick, self.batch
        first = True
        while state.drawn < len(batch.batches):
            # a chunk at least per call, more while the last one's time fits the budget
            if not first and time.perf_counter() - started + self.seconds["quick chunk"] > \
                    STAGE_SHARE * budget:
                return
            first = False
            t0 = time.perf_counter()
            state.draw(self.raster, batch.part(state.drawn, state.drawn + 1))
            self.seconds["quick chunk"] = time.perf_counter() - t0
        if not first and time.perf_counter() - started + \
                self.seconds.get("quick shade", 0.0) > STAGE_SHARE * budget:
            return
        t0 = time.perf_counter()
        arrays, gbuffer = state.source, state.gbuffer
        w, h = state.size
        if gbuffer is None:  # (no triangles)
            gbuffer = state.gbuffer = rasterize(arrays.tris, state.camera, arrays.rough, w, h,
                                                shader=self.raster, batch=ChunkedBatch())
        palette = np.zeros((1, len(arrays.palette), 4), np.float32)
        palette[0, :, :3] = arrays.palette
        world = snapshot.world
        colour = np.asarray(world.color, np.float32) * float(world.strength)
        out = gpu.types.GPUTexture((w, h), format="RGBA32F")
        shader = quick_shader()
        shader.bind()
        inputs = {**gbuffer.inputs, "palette": float_texture(palette, (len(arrays.palette), 1))}
        for name in QUICK_SAMPLERS:
            shader.uniform_sampler(name, inputs[name])
        shader.uniform_float("world", (*colour.tolist(), 0.0 if view.transparent else 1.0))
        shader.image("out_image", out)
        gpu.compute.dispatch(shader, -(-w // LOCAL_SIZE), -(-h // LOCAL_SIZE), 1)
        self.seconds["quick shade"] = time.perf_counter() - t0
        self.quick, self.coarse = None, state
        view.show(out)


def release() -> None:
    """Forget the prepared scene and the compiled lists, end the preparing thread (unregister,
    exit)."""
    worker.stop()
    preparation.free()
    warmup.__init__()
    _QUICK.clear()
    _waiting.clear()
    if bpy.app.timers.is_registered(wake_tick):
        bpy.app.timers.unregister(wake_tick)

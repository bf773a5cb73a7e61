"""Cycles bakes of a material's socket over a mesh's UVs: whole here, whole in a child
process, or a few texel blocks at a time (main thread; docs/gi_pipeline.md "Bakes a slice at
a time", "Material bakes in another process").

A bake renders a temporary copy of the material (its socket routed to what the bake writes:
``BakeSpec.route``) on a temporary copy of the mesh's faces of that material, in a temporary
scene, into a temporary image; everything is removed before the call returns, also when the
bake fails, so the user's file, its undo steps and its saves never hold any of it.

``bake_whole`` bakes the BAKE_SIZE² image in one Cycles bake: F12, ``render_preview`` and the
probe bakes wait for their image anyway. A bake costs 0.15–1.3 s (Cycles' shading of
BAKE_SIZE² × BAKE_SAMPLES samples, about 2 M a second on 2 cores), too long for the live
viewport's main thread. Its snapshots queue the bakes they need (``BakeQueue.want``) and read
the socket's plain value meanwhile; its timer (``BakeQueue.step``, ``viewport_session.tick``:
Blender forbids ``view_draw`` to write data) writes them — the mesh's faces and the routed
material copy, the object that holds them — to a .blend for a child process
(``blender.child_process``), which bakes them whole with the same code (``child_main``), and
collects what the child brought. A bake a child cannot make (its material reads an image only
in this session's memory, or its child failed) is baked here, a run of BLOCK × BLOCK texel
blocks of one row a tick, plus BAKE_MARGIN texels on every side, through a UV map (TILE_UV)
that puts the run's texels of the whole image on the small image's own. Texel for texel they
are the whole bake's texels (the same footprint, the same margin where an island crosses a
run's border); only Cycles' random samples differ.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import animated
from .world_process import WorldBakes

BAKE_SIZE = 512       # a baked socket's image: BAKE_SIZE² texels over the UV square
BAKE_SAMPLES = 8      # Cycles samples per texel (the texel's mean over its area)
BAKE_MARGIN = 4       # texels the bake extends each UV island by (no dark seams when filtered)
BLOCK = 32            # texels per side of the blocks a queued bake is baked in
TILE_UV = "VoxGI Bake Tile"  # the UV map a run of blocks is baked through
MAX_UV_MAPS = 8       # Blender's limit of UV maps per mesh
_COUNT = [0]


def busy_thread() -> str:
    """The name of another VoxGI thread that may run Python now ("" when none). A bake runs
    Blender's bake operator under a context override; the operator call lets go of Python's
    lock, and Blender then reads the override (a Python dict) without it: while another
    thread held the lock, that read crashed the process (measured: a thread of numpy beside
    tile bakes, within 50–200 bakes). The viewport bakes only while none does
    (``BakeQueue.step``). A thread that waits for work between tasks says whether it has any
    (its ``voxgi_busy()``, true from a task's submission on the main thread to its end);
    any other VoxGI thread counts while it is alive."""
    current = threading.current_thread()
    for thread in threading.enumerate():
        if thread is current or not thread.name.startswith("VoxGI") or not thread.is_alive():
            continue
        busy = getattr(thread, "voxgi_busy", None)
        if busy is None or busy():
            return thread.name
    return ""


def _rendering() -> bool:
    """Is a render job running (F12 in the UI: its Python runs on Blender's render thread,
    which the bake's unlocked read would race as any thread's)? A bake waits for its end."""
    return hasattr(bpy.app, "is_job_running") and bpy.app.is_job_running("RENDER")


def bake_count() -> int:
    """How many sockets Cycles baked this session (whole or queued, each counted once)."""
    return _COUNT[0]


@dataclass(frozen=True)
class BakeSpec:
    """What one bake renders, read while the snapshot holds the mesh.

    material : the user's material (``bpy.types.Material``); mode : "EMIT" or "DIFFUSE";
    route : route(tree, groups) makes the copy's node tree show the socket (copies of node
    groups it makes go to ``groups``, removed with the rest); slots : the mesh's material slot
    indices with this material, last : its last slot index (faces past it use it, as Blender
    draws them); render_uv : the UV map the nodes read (None: the mesh has none);
    target_uv : the UV map the bake writes through, AUTO_UVS' name with ``auto_uvs`` (the
    per-loop layout, which the copy gets as that map); matrix_world, object_color,
    pass_index : the object's (what object-space nodes and Object Info read); values : where
    the material is animated, its animated values at the snapshot's frame
    (``animated.frame_values``), which the copy takes, its own animation cleared; None
    otherwise; object_name : the object's name, whose hash is its Object Info › Random (the
    bake's object is named so that its Random is the same: ``same_random_name``); frame : the
    scene's frame, the bake's scene's (the picture of an image sequence or a movie)."""

    material: object
    mode: str
    route: Callable
    slots: tuple[int, ...]
    last: int
    render_uv: str | None
    target_uv: str | None
    auto_uvs: np.ndarray | None
    matrix_world: object
    object_color: tuple = (1.0, 1.0, 1.0, 1.0)
    pass_index: int = 0
    values: tuple | None = None
    object_name: str = ""
    frame: int = 1


def same_random_name(name: str, taken=None) -> str:
    """A name for a bake's object whose Object Info › Random (Cycles' hash of the name,
    ``object_random``) is the object ``name`` 's, that no object of this file has (``taken``:
    a container of names; default ``bpy.data.objects``): two neighbouring bytes a, b of its
    UTF-8 become a + k, b − 37 k (the hash steps by 37 a byte, so it stays) where the name
    stays printable UTF-8. "VoxGI Bake" where no pair allows it (its Random is then the bake
    object's own)."""
    taken = bpy.data.objects if taken is None else taken
    data = name.encode("utf-8")
    for i in range(len(data) - 1):
        a, b = data[i], data[i + 1]
        for k in (1, -1, 2, -2):
            x, y = a + k, b - 37 * k
            if not (0 < x < 256 and 0 < y < 256):
                continue
            try:
                candidate = (data[:i] + bytes((x, y)) + data[i + 2:]).decode("utf-8")
            except UnicodeDecodeError:
                continue
            if candidate.isprintable() and candidate not in taken:
                return candidate
    return "VoxGI Bake"


def bake_whole(spec: BakeSpec, mesh) -> np.ndarray | None:
    """(BAKE_SIZE, BAKE_SIZE, 3) float32 linear RGB (row 0 = V 0) of the socket over
    ``mesh`` (an evaluated mesh), or None where no face of it has the material."""
    _COUNT[0] += 1
    source = _source_mesh(spec, mesh)
    if source is None:
        return None
    try:
        with _Baking(spec, source) as baking:
            return baking.bake(0, 0, BAKE_SIZE, BAKE_SIZE)
    finally:
        bpy.data.meshes.remove(source)


def _source_mesh(spec: BakeSpec, evaluated):
    """A temporary copy of ``evaluated``'s faces of the material (all in slot 0), its bake's
    UV map active (what the bake writes through) and the render one active for rendering
    (what the nodes read); None when no face has the material."""
    import bmesh

    mesh = bpy.data.meshes.new("VoxGI Bake")
    try:
        source, target = evaluated, spec.target_uv
        if spec.auto_uvs is not None:  # the layout as the bake's UV map
            bm = bmesh.new()
            try:
                bm.from_mesh(source)
                bm.to_mesh(mesh)
            finally:
                bm.free()
            mesh.uv_layers.new(name=target).data.foreach_set(
                "uv", np.ascontiguousarray(spec.auto_uvs, np.float32).ravel())
            source = mesh
        bm = bmesh.new()
        try:
            bm.from_mesh(source)
            others = [f for f in bm.faces if min(f.material_index, spec.last) not in spec.slots]
            if others:
                bmesh.ops.delete(bm, geom=others, context="FACES")
            for face in bm.faces:
                face.material_index = 0
            bm.to_mesh(mesh)
        finally:
            bm.free()
        if not mesh.polygons:  # the material is in a slot no face of this mesh uses
            bpy.data.meshes.remove(mesh)
            return None
        if target is not None and mesh.uv_layers.get(target) is not None:
            mesh.uv_layers.active = mesh.uv_layers[target]
        if spec.render_uv is not None and mesh.uv_layers.get(spec.render_uv) is not None:
            mesh.uv_layers[spec.render_uv].active_render = True
        return mesh
    except BaseException:
        bpy.data.meshes.remove(mesh)
        raise


class _Baking:
    """The temporary material copy, object and scene of one bake call's runs (``bake``). With
    ``staged`` False only the object (and its material copy), for a child to bake
    (``_Batch``); ``loaded`` stages such an object in the child."""

    def __init__(self, spec: BakeSpec | None, source, tile_uvs: np.ndarray | None = None,
                 staged: bool = True):
        self.spec, self.source, self.tile_uvs, self.staged = spec, source, tile_uvs, staged
        self.mode = None if spec is None else spec.mode
        self.frame = 1 if spec is None else spec.frame
        self.copy = self.obj = self.scene = None
        self.groups: list = []
        self.owned = True  # the object and its material copy are removed on exit

    @classmethod
    def loaded(cls, obj, mode: str) -> _Baking:
        """A bake of ``obj`` as ``_Batch`` wrote it (its mesh, its routed material)."""
        baking = cls(None, obj.data)
        baking.obj, baking.copy, baking.mode, baking.owned = obj, obj.data.materials[0], mode, False
        baking.frame = int(obj.get(_FRAME, 1))
        return baking

    def __enter__(self):
        try:
            if self.obj is None:
                self.copy = self.spec.material.copy()
                if self.spec.values is not None:  # animated: its values at the render's frame
                    self.groups += animated.apply(self.copy, self.spec.values)
                self.spec.route(self.copy.node_tree, self.groups)
                self.source.materials.clear()
                self.source.materials.append(self.copy)
                self.obj = bpy.data.objects.new(same_random_name(self.spec.object_name),
                                                self.source)
                self.obj.matrix_world = self.spec.matrix_world
                self.obj.color = self.spec.object_color
                self.obj.pass_index = self.spec.pass_index
            if not self.staged:
                return self
            self.scene = bpy.data.scenes.new("VoxGI Bake")
            self.scene.frame_current = self.frame  # (an image sequence's or movie's picture)
            self.scene.collection.objects.link(self.obj)
            self.scene.render.engine = "CYCLES"
            cycles = self.scene.cycles
            cycles.device = "CPU"
            cycles.samples = BAKE_SAMPLES
            cycles.use_denoising = False
            cycles.seed = 0
            settings = self.scene.render.bake
            settings.margin = BAKE_MARGIN
            settings.margin_type = "EXTEND"
            settings.use_clear = True
            settings.use_selected_to_active = False
            settings.target = "IMAGE_TEXTURES"
            view_layer = self.scene.view_layers[0]
            self.obj.select_set(True, view_layer=view_layer)
            view_layer.objects.active = self.obj
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def bake(self, x0: int, y0: int, width: int, height: int) -> np.ndarray:
        """(height, width, 3) float32: the whole image's texels [y0, y0 + height) ×
        [x0, x0 + width): through the bake's UV map for the whole image, else through TILE_UV
        (``_tiled``), the bake's UVs ``tile_uvs`` moved so that those texels fill the image,
        texel centres on texel centres."""
        if self.tile_uvs is not None:
            placed = (self.tile_uvs * np.float32(BAKE_SIZE) - np.array([x0, y0], np.float32)) \
                / np.array([width, height], np.float32)
            self.source.uv_layers[TILE_UV].data.foreach_set(
                "uv", np.ascontiguousarray(placed, np.float32).ravel())
        image = bpy.data.images.new("VoxGI Bake", width, height, float_buffer=True, alpha=False)
        try:
            node = self.copy.node_tree.nodes.new("ShaderNodeTexImage")
            node.image = image
            self.copy.node_tree.nodes.active = node
            kwargs = {"type": self.mode, "margin": BAKE_MARGIN, "use_clear": True}
            if self.mode == "DIFFUSE":
                kwargs["pass_filter"] = {"COLOR"}
            view_layer = self.scene.view_layers[0]
            with bpy.context.temp_override(scene=self.scene, view_layer=view_layer,
                                           active_object=self.obj, object=self.obj,
                                           selected_objects=[self.obj],
                                           selected_editable_objects=[self.obj]):
                result = bpy.ops.object.bake(**kwargs)
            if "FINISHED" not in result:
                raise RuntimeError(f"the bake returned {result}")
            pixels = np.empty(width * height * 4, np.float32)
            image.pixels.foreach_get(pixels)
            self.copy.node_tree.nodes.remove(node)
            return np.ascontiguousarray(pixels.reshape(height, width, 4)[..., :3])
        finally:
            bpy.data.images.remove(image)

    def __exit__(self, *_exc) -> None:
        if self.scene is not None:
            bpy.data.scenes.remove(self.scene)
        if self.obj is not None and self.owned:
            bpy.data.objects.remove(self.obj)
        if self.copy is not None and self.owned:
            bpy.data.materials.remove(self.copy)
        for group in self.groups:
            bpy.data.node_groups.remove(group)
        self.scene = self.obj = self.copy = None
        self.groups = []


def _bake_uvs(mesh) -> np.ndarray:
    """(L, 2) float32: the UVs the bake writes through (the active map's; TILE_UV's source)."""
    layer = mesh.uv_layers.active
    uvs = np.empty(len(mesh.loops) * 2, np.float32)
    layer.data.foreach_get("uv", uvs)
    return uvs.reshape(-1, 2)


def _tiled(source) -> np.ndarray:
    """Add TILE_UV to ``source`` as its active UV map (the bake's target; the render one
    stays what the nodes read); the bake's own UVs (L, 2). ValueError when the mesh has no
    room for another UV map."""
    uvs = _bake_uvs(source)
    if len(source.uv_layers) >= MAX_UV_MAPS:
        raise ValueError(f"the mesh has {len(source.uv_layers)} UV maps, Blender's most")
    render = next((layer.name for layer in source.uv_layers if layer.active_render), None)
    layer = source.uv_layers.new(name=TILE_UV)
    source.uv_layers.active = layer
    if render is not None:
        source.uv_layers[render].active_render = True
    return uvs


def covered_blocks(mesh, uvs: np.ndarray) -> np.ndarray:
    """(B, B) bool, B = BAKE_SIZE // BLOCK, row 0 = V 0: the blocks a polygon's UV bounds
    (widened by the margin) reach; the rest of the image stays black, as the whole bake's."""
    side = BAKE_SIZE // BLOCK
    covered = np.zeros((side, side), bool)
    starts = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    if len(starts) == 0 or len(uvs) == 0:
        return covered
    texels = np.nan_to_num(uvs * np.float32(BAKE_SIZE), nan=-1e9)
    low = np.minimum.reduceat(texels, starts, axis=0) - BAKE_MARGIN - 1
    high = np.maximum.reduceat(texels, starts, axis=0) + BAKE_MARGIN + 1
    first = np.clip(np.floor(low / BLOCK), 0, side - 1).astype(np.int64)
    last = np.clip(np.floor(high / BLOCK), 0, side - 1).astype(np.int64)
    inside = (high > 0).all(axis=1) & (low < BAKE_SIZE).all(axis=1)
    spans = np.unique(np.concatenate([first, last], axis=1)[inside], axis=0)
    for x0, y0, x1, y1 in spans:
        covered[y0:y1 + 1, x0:x1 + 1] = True
    return covered


@dataclass
class BakeRequest:
    """A queued bake: ``spec`` over the evaluated mesh of ``object_name`` (``loops`` corners
    when queued), ``store(pixels)`` called with the whole image when every block is baked."""

    spec: BakeSpec
    object_name: str
    loops: int
    store: Callable
    pixels: np.ndarray | None = None
    todo: np.ndarray | None = None        # (B, B) bool: blocks still to bake
    block_seconds: float | None = None    # measured: one block's bake, its call's share included


@dataclass
class _BakeChild:
    """A batch of queued bakes baked whole in a child process (``BakeQueue._send``): its
    directory holds the batch's .blend and, as each bake ends, ``<stem>.npy``."""

    child: object            # child_process.Child
    stems: dict[str, str]    # file stem → the request's key


@dataclass
class BakeQueue:
    """The live viewport's pending bakes, keyed by their content key (``want``), baked by
    child processes and collected by its timer (``step``). A snapshot taken with the queue
    ``begin`` s and ``end`` s its wants: a bake no snapshot wants any more is dropped.
    ``failed`` keeps why a bake could not run, so the next snapshot warns instead of queueing
    it again; ``finished`` the materials whose bakes completed (for the viewport to read
    again); ``empty`` the bakes of a material no face of its mesh has (nothing to bake or
    show); ``local`` the bakes a child cannot make (an image only in this session's memory, a
    child that failed), baked here a run of blocks a step. ``worlds``: the node-built worlds
    baked in other processes (``world_process``), which ``step`` polls."""

    requests: dict[str, BakeRequest] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)
    finished: set[str] = field(default_factory=set)
    empty: set[str] = field(default_factory=set)  # bakes of a material on no face of its mesh
    local: set[str] = field(default_factory=set)
    worlds: WorldBakes = field(default_factory=WorldBakes)
    child: _BakeChild | None = None
    _wanted: set[str] | None = None

    @property
    def pending(self) -> int:
        return len(self.requests) + self.worlds.pending

    def begin(self) -> None:
        self._wanted = set()

    def want(self, key: str, request: Callable[[], BakeRequest]) -> None:
        if self._wanted is not None:
            self._wanted.add(key)
        if key not in self.requests:
            self.requests[key] = request()

    def end(self) -> None:
        if self._wanted is not None:
            for key in [k for k in self.requests if k not in self._wanted]:
                del self.requests[key]
        self._wanted = None

    def clear(self) -> None:
        self.requests.clear()
        self.failed.clear()
        self.finished.clear()
        self.empty.clear()
        self.local.clear()
        self.worlds.clear()
        self._stop_child()

    def step(self, seconds: float, depsgraph) -> bool:
        """One tick of the queue (about ``seconds`` of the main thread at most): collect the
        worlds' and the materials' bakes that children ended; with no child running, write
        the next batch of queued bakes for one (``_send``); else bake runs of blocks of the
        first ``local`` bake here, unless another VoxGI thread or a render job runs
        (``busy_thread``, ``_rendering``). Whether anything was done. A bake whose object or
        material is gone is dropped (the deletion's update reads the scene again); one that
        fails, or whose object's mesh is not the one the snapshot read, is kept in
        ``failed``."""
        from .world_map import store

        worked = self.worlds.poll(store)
        worked = self._collect() or worked
        if _rendering():
            return worked
        if self.child is None and any(k not in self.local for k in self.requests):
            return self._send(seconds, depsgraph) or worked
        key = next((k for k in self.requests if k in self.local), None)
        if key is None or busy_thread():
            return worked
        request = self.requests[key]
        try:
            done = _bake_runs(request, seconds, depsgraph)
        except _Gone:
            del self.requests[key]
            self.local.discard(key)
            return True
        except Exception as error:  # noqa: BLE001 - a failed bake must not stop the view
            del self.requests[key]
            self.local.discard(key)
            self.failed[key] = str(error) or type(error).__name__
            return True
        if done:
            self._done(key, request, request.pixels)
        return True

    def step_for_render(self, seconds: float, depsgraph) -> bool:
        """``step`` for an F12 in the UI (``RenderBakes.serve``, main thread, while the render
        job waits): what children baked collected, the next batch sent; a bake a child cannot
        make (an image only in this session's memory, a child that failed) fails, since none
        may run here beside a render job. True when none is left."""
        self._collect()
        for key in [k for k in self.requests if k in self.local]:
            del self.requests[key]
            self.failed[key] = ("no other process could bake it (an image only in this "
                                "session's memory, or a failed child: see the console), and "
                                "none may run beside an F12 render in the UI")
        self.local.clear()
        if self.child is None and self.requests:
            self._send(seconds, depsgraph)
        return not self.requests

    def _done(self, key: str, request: BakeRequest, pixels) -> None:
        del self.requests[key]
        self.local.discard(key)
        if pixels is None:
            self.empty.add(key)
            return
        request.store(pixels)
        try:
            self.finished.add(request.spec.material.name_full)
        except ReferenceError:  # deleted since: its deletion's update reads the scene again
            return

    def _send(self, seconds: float, depsgraph) -> bool:
        """Write the queued bakes (as many as about ``seconds`` hold, at least one) to a
        .blend and start a child that bakes them whole (``child_main``). A bake whose
        material reads an image a child cannot see goes to ``local``."""
        import shutil

        from ..child_process import Child, sees_images, workspace

        start = time.perf_counter()
        directory = workspace("voxgi-bake-child-")
        stems: dict[str, str] = {}
        sources = []
        try:
            with _Batch() as batch:
                for key, request in list(self.requests.items()):
                    if key in self.local:
                        continue
                    if stems and time.perf_counter() - start > seconds:
                        break
                    try:
                        if not sees_images(request.spec.material.node_tree):
                            self.local.add(key)
                            continue
                        source = _evaluated_source(request, depsgraph)
                    except (_Gone, ReferenceError):  # (its material deleted)
                        del self.requests[key]
                        continue
                    except Exception as error:  # noqa: BLE001 - said, the rest go on
                        del self.requests[key]
                        self.failed[key] = str(error) or type(error).__name__
                        continue
                    if source is None:
                        self._done(key, request, None)
                        continue
                    sources.append(source)
                    stem = f"bake{len(stems)}"
                    batch.add(request.spec, source, stem)
                    stems[stem] = key
                if stems:
                    batch.write(os.path.join(directory, BATCH_FILE))
        finally:
            for source in sources:
                bpy.data.meshes.remove(source)
        if not stems:
            shutil.rmtree(directory, ignore_errors=True)
            return True
        try:
            child = Child.start("blender.snapshot.bakes",
                                [os.path.join(directory, BATCH_FILE), directory], directory)
        except OSError as error:  # no child here: every bake of the batch is baked here
            self.local.update(stems.values())
            print(f"VoxGI: material bakes in a child process could not start ({error})")
            return True
        _COUNT[0] += len(stems)
        self.child = _BakeChild(child, stems)
        return True

    def _collect(self) -> bool:
        """Store what the running child baked so far; when it has ended, the bakes it did not
        bring go to ``local`` (baked here). Whether anything came in or ended."""
        batch = self.child
        if batch is None:
            return False
        ended = batch.child.ended() is not None
        got = False
        for stem, key in list(batch.stems.items()):
            path = batch.child.path(stem + ".npy")
            if not os.path.exists(path):
                continue
            del batch.stems[stem]
            got = True
            request = self.requests.get(key)
            if request is None:  # wanted no more
                continue
            try:
                pixels = np.load(path)
            except Exception as error:  # noqa: BLE001 - an unreadable image: baked here
                print(f"VoxGI: a material bake from a child process could not be read ({error})")
                self.local.add(key)
                continue
            self._done(key, request, pixels)
        if not ended and not any(key in self.requests for key in batch.stems.values()):
            self._stop_child()  # wanted no more (an edit since): the next batch need not wait
            return True
        if ended:
            missing = [key for key in batch.stems.values() if key in self.requests]
            if missing:
                print(f"VoxGI: {len(missing)} material bake(s) failed in a child process "
                      f"({batch.child.tail()}); baking them here")
                self.local.update(missing)
            self._stop_child()
            got = True
        return got

    def _stop_child(self) -> None:
        batch, self.child = self.child, None
        if batch is not None:
            batch.child.stop()


class RenderBakes:
    """The material bakes of an F12 in Blender's UI. Its render runs on a job thread, where no
    bake may run and no data may be written: its snapshot queues the bakes it needs
    (``BakeQueue.want``), hands the queue here (``bake``, the render thread) and waits while
    the main thread's timer (``kernel_warmup``, ``serve`` a tick) writes them for child
    processes as the viewport's timer does (``BakeQueue.step_for_render``) and collects their
    images; then the snapshot is read again with the bakes in the cache. The timer is
    registered in Blender's UI only (``served``); elsewhere the snapshot bakes in place or says
    why it cannot."""

    WAIT = 300.0     # seconds the render waits for its bakes before it uses their values
    SECONDS = 0.02   # of the main thread a tick may write bakes for a child

    def __init__(self):
        self.served = False
        self.lock = threading.Lock()
        self._asked: tuple[BakeQueue, object, threading.Event] | None = None
        self._worlds: list[tuple[tuple, threading.Event]] = []
        self._local = threading.local()

    @contextlib.contextmanager
    def watching(self, cancelled: Callable[[], bool]):
        """While this block runs (on a render's thread), a wait for bakes ends early when
        ``cancelled()`` (``RenderEngine.test_break``: the user pressed Esc)."""
        before = getattr(self._local, "cancelled", None)
        self._local.cancelled = cancelled
        try:
            yield
        finally:
            self._local.cancelled = before

    def cancelled(self) -> bool:
        """Whether this thread's render was cancelled (``watching``)."""
        check = getattr(self._local, "cancelled", None)
        try:
            return bool(check is not None and check())
        except ReferenceError:  # (the engine is gone)
            return True

    def available(self) -> bool:
        """Whether a snapshot here can hand its bakes to the main thread: off it (a render
        thread), with the timer that serves them registered."""
        return self.served and threading.current_thread() is not threading.main_thread()

    def bake(self, queue: BakeQueue, depsgraph, wait: float | None = None) -> bool:
        """Hand ``queue`` 's requests, over the evaluated meshes of ``depsgraph``, to the main
        thread and wait until each is baked, failed (its reason in ``queue.failed``) or on no
        face (``queue.empty``), at most ``wait`` seconds (``WAIT``); those left then fail.
        Whether every bake came in."""
        done = threading.Event()
        with self.lock:
            if self._asked is not None:  # one render job at a time: an older ask is over
                self._asked[2].set()
            self._asked = (queue, depsgraph, done)
        limit = time.monotonic() + (self.WAIT if wait is None else wait)
        finished = False
        while not finished and time.monotonic() < limit and not self.cancelled():
            finished = done.wait(min(0.1, max(limit - time.monotonic(), 0.0)))
        with self.lock:
            if self._asked is not None and self._asked[2] is done:
                self._asked = None
            queue._stop_child()
            why = "the render was cancelled" if self.cancelled() else \
                "its bake in another process did not end in time"
            for key in list(queue.requests):
                queue.failed[key] = why
                del queue.requests[key]
        return finished

    def start_world(self, world, key: str, height: int, uses_light_path: bool,
                    frame: int = 1) -> bool:
        """Have the main thread start a child baking ``world`` (the render's evaluated copy:
        its animated values go with it) into ``world_process.ahead`` under ``key``, and wait
        until it has started (a render thread: then it waits for the map,
        ``WorldBakes.wait``). Whether it started."""
        from . import animated
        from .world_process import ahead

        started = threading.Event()
        ask = (animated.original(world).name_full, key, height, uses_light_path,
               animated.frame_values(world), frame)
        with self.lock:
            self._worlds.append((ask, started))
        limit = time.monotonic() + self.WAIT
        while not started.wait(0.1):
            if time.monotonic() > limit or self.cancelled():
                with self.lock:
                    if (ask, started) in self._worlds:
                        self._worlds.remove((ask, started))
                return False
        return key in ahead.running

    def _start_worlds(self) -> None:
        """Start the children the render asked for (``start_world``; main thread, lock held)."""
        from .world_process import ahead

        for (name, key, height, uses_light_path, values, frame), started in self._worlds:
            world = bpy.data.worlds.get(name)
            try:
                with ahead.lock:
                    if world is None:
                        ahead.failed[key] = f"the world '{name}' is gone"
                    else:
                        ahead.want(world, key, height, uses_light_path, values, frame)
            except Exception as error:  # noqa: BLE001 - the render lights with the Background
                ahead.failed[key] = str(error) or type(error).__name__
            started.set()
        self._worlds.clear()

    def serve(self) -> bool:
        """One tick of the main thread's timer: the world children a render asked for started
        (``start_world``), a step of the asked material bakes, if any (``bake``). Whether
        anything was asked (the timer ticks again soon)."""
        with self.lock:
            worlds = bool(self._worlds)
            self._start_worlds()
            if self._asked is None:
                return worlds
            queue, depsgraph, done = self._asked
            try:
                finished = queue.step_for_render(self.SECONDS, depsgraph)
            except Exception as error:  # noqa: BLE001 - the render uses the values, said
                for key in list(queue.requests):
                    queue.failed[key] = str(error) or type(error).__name__
                queue.requests.clear()
                finished = True
            if finished:
                self._asked = None
                done.set()
            return not finished


render_bakes = RenderBakes()


BATCH_FILE = "bakes.blend"
_STEM = "voxgi_bake_stem"  # the custom properties a batch's objects carry for the child
_MODE = "voxgi_bake_mode"
_NAME, _OWNER = "voxgi_bake_name", "voxgi_bake_owner"  # its name, the object it bakes for
_FRAME = "voxgi_bake_frame"


class _Batch:
    """The objects of a child's batch (``BakeQueue._send``): each bake's object and routed
    material copy (``_Baking`` unstaged), written to one .blend, removed on exit."""

    def __init__(self):
        self.bakings: list[_Baking] = []

    def __enter__(self):
        return self

    def add(self, spec: BakeSpec, source, stem: str) -> None:
        baking = _Baking(spec, source, staged=False)
        self.bakings.append(baking.__enter__())
        baking.obj[_STEM], baking.obj[_MODE] = stem, spec.mode
        baking.obj[_NAME], baking.obj[_OWNER] = baking.obj.name, spec.object_name
        baking.obj[_FRAME] = spec.frame

    def write(self, path: str) -> None:
        # images by absolute paths: the child opens the file elsewhere
        bpy.data.libraries.write(path, {b.obj for b in self.bakings}, path_remap="ABSOLUTE",
                                 compress=False)

    def __exit__(self, *_exc) -> None:
        for baking in self.bakings:
            baking.__exit__(None, None, None)
        self.bakings.clear()


def child_main(args: list[str]) -> int:
    """A child (``blender.child_process``): ``BLEND DIRECTORY``: bake each object of the batch
    ``BLEND`` whole, as ``bake_whole`` does here, into ``DIRECTORY/<stem>.npy`` as it ends
    (whole or nothing: written, then renamed)."""
    blend, directory = args
    with bpy.data.libraries.load(blend, link=False) as (source, target):
        target.objects = list(source.objects)
    for obj in target.objects:
        stem, mode = str(obj[_STEM]), str(obj[_MODE])
        if obj.get(_NAME) and obj.name != obj[_NAME]:  # (renamed on loading here: its Random)
            obj.name = same_random_name(str(obj[_OWNER]))
        with _Baking.loaded(obj, mode) as baking:
            pixels = baking.bake(0, 0, BAKE_SIZE, BAKE_SIZE)
        partial = os.path.join(directory, stem + ".part.npy")
        np.save(partial, pixels)
        os.replace(partial, os.path.join(directory, stem + ".npy"))
    return 0


class _Gone(Exception):
    """What a queued bake reads is gone or changed: drop it."""


def _evaluated_source(request: BakeRequest, depsgraph):
    """The bake's temporary mesh (``_source_mesh``) of its object's evaluated mesh, None when
    no face has the material; ``_Gone`` when the object or material is gone, RuntimeError
    when the object's mesh is not the one the snapshot read."""
    spec = request.spec
    obj = bpy.data.objects.get(request.object_name)
    try:
        material_name = spec.material.name_full
    except ReferenceError:
        raise _Gone() from None
    if obj is None or bpy.data.materials.get(material_name) is None:
        raise _Gone()
    obj_eval = obj.evaluated_get(depsgraph)
    evaluated = obj_eval.to_mesh()
    try:
        if evaluated is None or len(evaluated.loops) != request.loops:
            # an edit since the snapshot (whose own update queues the new bake; this one is
            # wanted no more), or geometry the object does not hold itself (an instance of
            # generated geometry): said, not tried again
            raise RuntimeError(f"'{request.object_name}' no longer has the mesh the snapshot "
                               "read (an instance of generated geometry?)")
        return _source_mesh(spec, evaluated)
    finally:
        obj_eval.to_mesh_clear()


def _bake_runs(request: BakeRequest, seconds: float, depsgraph) -> bool:
    """``BakeQueue.step`` for one ``local`` request; True when its image is complete (its
    ``pixels``; None when no face has the material)."""
    start = time.perf_counter()
    source = _evaluated_source(request, depsgraph)
    if source is None:  # no face of the mesh has the material: nothing to bake, nothing seen
        request.pixels = None
        return True
    try:
        try:
            uvs = _tiled(source)
        except ValueError:  # no room for TILE_UV: the whole image in this one call
            with _Baking(request.spec, source) as baking:
                request.pixels = baking.bake(0, 0, BAKE_SIZE, BAKE_SIZE)
            _COUNT[0] += 1
            return True
        if request.todo is None:
            _COUNT[0] += 1
            request.todo = covered_blocks(source, uvs)
            request.pixels = np.zeros((BAKE_SIZE, BAKE_SIZE, 3), np.float32)
        ran = False
        with _Baking(request.spec, source, uvs) as baking:
            while request.todo.any():
                left = seconds - (time.perf_counter() - start)
                if ran and (request.block_seconds is None or left < request.block_seconds):
                    break
                row, first, count = _next_run(request.todo, left, request.block_seconds)
                t0 = time.perf_counter()
                x0, y0, width = first * BLOCK, row * BLOCK, count * BLOCK
                texels = baking.bake(x0 - BAKE_MARGIN, y0 - BAKE_MARGIN,
                                     width + 2 * BAKE_MARGIN, BLOCK + 2 * BAKE_MARGIN)
                request.pixels[y0:y0 + BLOCK, x0:x0 + width] = \
                    texels[BAKE_MARGIN:BAKE_MARGIN + BLOCK, BAKE_MARGIN:BAKE_MARGIN + width]
                request.todo[row, first:first + count] = False
                request.block_seconds = (time.perf_counter() - t0) / count
                ran = True
    finally:
        bpy.data.meshes.remove(source)
    return not request.todo.any()


def _next_run(todo: np.ndarray, left: float, block_seconds: float | None
              ) -> tuple[int, int, int]:
    """(row, first block, count): the first row's first run of blocks to bake, as many as
    ``left`` seconds hold at ``block_seconds`` a block (one while that is unmeasured)."""
    row = int(np.argmax(todo.any(axis=1)))
    first = int(np.argmax(todo[row]))
    end = first
    while end < todo.shape[1] and todo[row, end]:
        end += 1
    most = 1 if block_seconds is None or block_seconds <= 0 else \
        max(1, int(left / block_seconds))
    return row, first, min(end - first, most)

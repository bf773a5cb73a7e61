"""Live GI for the 3D view: one ``LiveGI`` per scene schedules the cheapest correct work for
each batch of depsgraph updates and runs it on the engine worker (main thread only).

The render engine's ``view_update`` hands its depsgraph to ``LiveGI.update``: the updates
become records (``updates.py``), the planner (``voxgi_addon/scene/changes.py``) turns them
into stages, and ``schedule`` takes the snapshot (the main thread's only CPU work: a full
snapshot with ``foreach_get``, or matrices / poses / lights only for transform changes) and
submits one job to the worker (``jobs.py``):

    refresh_caches (voxelize only keys whose fingerprint changed; ``voxelize/incremental``)
    → update_gi_stages (cascades, injection, octree; cascades reused for light-only changes)
    → volume_atlas (the octree's GPU layout, so the main thread only uploads it; for Fast)
    → Fast at Bounces > 1: bounced_volumes (the octrees rebuilt with the view's radiance
      cache and their layouts; ``bounce_cache``, ``render/viewport_bounces.py``)

A newer change supersedes the queued or running job; its plan is merged into the newer one so
no work is lost. Results are applied on the main thread (``jobs.drain``), become the scene's
results for F12 and the panels too (``session.py``), and tag the 3D views for redraw;
``view_draw`` traces and draws them (``render/viewport.py``). A cancelled or failing job leaves
the previous results in use; the error is kept for the panel. Accurate quality traces the
scene's triangles, not the voxels: the view traces the snapshot as soon as it is taken
(``image_source``), while the worker still builds the voxels for Fast, F12 and the panels.

Undo/redo and file loads: a file load clears every ``LiveGI``; after undo/redo the next update
re-reads the whole scene, and cache fingerprints decide what is voxelized again
(``voxelize/incremental``), so no stale cache survives an undo.
"""
from __future__ import annotations

import dataclasses
import time
import traceback
from dataclasses import dataclass, field

import bpy

from ..registration import add_handlers, remove_handlers
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.incremental import StagedGI, cascade_grids, grids_equal, update_gi_stages
from ..voxgi_addon.preview.bounced_volumes import bounced_volumes
from ..voxgi_addon.preview.volume_textures import volume_atlas
from ..voxgi_addon.scene.changes import (
    SceneIndex,
    StageCounter,
    UpdatePlan,
    UpdateRecord,
    full_plan,
    plan_updates,
    view_plan,
)
from ..voxgi_addon.voxelize.incremental import CacheStore, refresh_caches
from . import jobs
from .redraw import tag_3d_views
from .session import scene_session
from .settings import gi_settings
from .snapshot import snapshot_or_error, snapshot_summary
from .snapshot.bakes import BakeQueue
from .snapshot.mesh_cache import MeshReads
from .snapshot.scene import read_ahead
from .updates import (
    records_from_depsgraph,
    remembered_index,
    scene_index,
    skin_states,
    transform_snapshot,
    without_skin_echo,
    world_state,
    world_touched,
)

JOB_LABEL = "Updating viewport GI"
MEGABYTE = 1_000_000
# seconds of a full snapshot's mesh reads per view_update or draw (``LiveGI.read_on``)
READ_SLICE = 0.008
# seconds of the queued material bakes per timer tick (``tick``: bakes written for a child
# process, or a run of texel blocks baked here, its length from the last run's time), and the
# tick's interval: the draws and the events of the UI run between two ticks
BAKE_SLICE = 0.02
TICK_INTERVAL = 0.01


@dataclass
class LiveResult:
    """What one job produced (worker side), applied on the main thread."""

    snapshot: object
    caches: object
    staged: StagedGI
    atlas: object
    voxelized: list[str]
    reused: list[str]
    timings: dict[str, float]
    bounced: object = None  # BouncedVolumes of the new state with ``LiveGI.bounce_cache``


@dataclass
class LiveStats:
    """The last applied update, for the panels: why, what ran, how long, how big."""

    triggers: tuple[str, ...] = ()
    stages: tuple[str, ...] = ()
    voxelized: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    cascades: list[tuple[int, float, int, float]] = field(default_factory=list)  # i, span, voxels, MB
    octree_nodes: int = 0
    octree_mb: float = 0.0
    cache_mb: float = 0.0


def settings_key(scene) -> tuple:
    """(voxel settings, cascade settings) of the scene: a change of the first re-voxelizes
    everything, of the second rebuilds the cascades (``LiveGI.update``)."""
    s = scene.voxgi
    return ((round(s.base_span, 9), s.cascade_count), (gi_settings(s),))


class LiveGI:
    """The viewport's results and scheduling for one scene (see the module doc)."""

    def __init__(self, scene_name: str):
        self.scene_name = scene_name
        self.store = CacheStore()
        self.snapshot = None       # the applied result's snapshot (camera = the view's)
        self.staged: StagedGI | None = None
        self.atlas = None
        self.generation = 0        # bumped per applied result: view_draw traces again
        self.index: SceneIndex | None = None  # of the last snapshot taken
        self.latest_snapshot = None  # the last snapshot taken (maybe not applied yet)
        self.snapshots = 0         # bumped per new snapshot taken (Accurate's image key)
        self.planned = StageCounter()  # every plan scheduled
        self.plans: list[UpdatePlan] = []  # the same, in order (tests, panel)
        self.pending: UpdatePlan | None = None  # the plan of the running job
        self.view_camera = None    # CameraData of the last drawn view (anchors the cascades)
        self.view_status = ""      # the 3D view's status line (render/viewport.py status_line)
        self.view_shown = ""       # what it drew last: "Coarse", "Refining", "Converged",
        #                            "Cached", "Previous" (render/viewport.py draw_view)
        self.view_samples = (0, 0)  # (samples done, target) of the view's accumulation
        self.error = ""
        # the snapshot of a view layer that shows no mesh (its world, camera, film), else None
        self.world_only = None
        self.stats = LiveStats()
        self.progress = jobs.Progress()
        self.settings = None
        self.rescan = ""           # why everything must be read again next time ("" = no need)
        # the last snapshot's mesh reads, reused by the next full snapshot for the meshes
        # whose geometry no update touched (snapshot/mesh_cache.py)
        self.mesh_reads = MeshReads()
        # (snapshot, state, version) an Accurate view finishes before the latest snapshot,
        # set by the view for its draw (render/viewport_prepare.hold_source), else None
        self.held_source = None
        # a full snapshot's plan while its meshes are read ahead, a slice per view_update or
        # draw (``read_on``; docs/gi_pipeline.md "Snapshots that read only what changed"):
        # the job is submitted when they are all read. read_slice : seconds of reads per
        # slice, set by the render engine's view_update (draws follow to go on with them);
        # None (the default: a caller that does not draw) reads everything at once.
        self.reading: UpdatePlan | None = None
        self.read_slice: float | None = None
        self.read_all = False  # every mesh read ahead, and no update since: snapshot next
        # the material bakes full snapshots queued (their values read meanwhile), baked a
        # slice a timer tick (``tick``); the materials read again when the last is baked
        self.bakes = BakeQueue()
        self.skin: dict[str, tuple[bytes, bytes]] = {}  # skinned objects' states (``update``)
        self.world = None          # updates.world_state at the last snapshot
        self.world_changed = True  # the next posed snapshot reads the world again
        # Fast quality at Bounces > 1: the radiance cache the view's voxels reflect (set by the
        # view, render/viewport_bounces.py; None otherwise): a job submitted while it is set
        # also rebuilds the new state's octrees with it on the worker, so the view shows the
        # moved scene with its bounces at once (``bounced``: those of the applied result)
        self.bounce_cache = None
        self.bounced = None

    # ------------------------------------------------------------------ planning

    def update(self, scene, depsgraph, records=None) -> UpdatePlan:
        """``view_update``: plan the depsgraph's updates (or ``records``) and schedule them."""
        if records is None:
            records = records_from_depsgraph(depsgraph, self.index)
        self.read_all = False  # (the reads ahead are checked again)
        # every update is seen here, also those that plan nothing: the kept mesh reads forget
        # what they may have changed (before the skinned objects' echo is told apart)
        self.mesh_reads.forget_updated(records, _mesh_data_name, _shape_keys_mesh)
        # A full snapshot of a skinned mesh adds and removes a temporary modifier
        # (snapshot/skin.py), which Blender reports as a geometry update of it: our own echo,
        # told apart from edits and poses by the mesh's rest shape and pose fingerprints.
        records = without_skin_echo(records, self.skin, depsgraph)
        self.world_changed = self.world_changed or world_touched(records, scene, self.world)
        key = settings_key(scene)
        if self.index is None or self.rescan:
            plan = full_plan(self.rescan or "first update")
            self.bakes.failed.clear()  # (undo may bring back what a failed bake read)
            if self.rescan or self.reading is None:
                # undo, a new engine: updates may have been missed (while the first
                # snapshot's meshes are read ahead, this one sees every update)
                self.mesh_reads.clear()
        elif key[0] != self.settings[0]:
            plan = full_plan("voxel settings changed")
        else:
            plan = plan_updates(records, self.index)
            if key[1] != self.settings[1]:
                plan = plan.merged(view_plan(True)).merged(
                    UpdatePlan(frozenset({"snapshot"}), triggers=("cascade settings changed",)))
        self.settings = key
        self.rescan = ""
        if not plan.empty:
            self.schedule(plan, scene, depsgraph)
        return plan

    def view_changed(self, camera, scene=None, depsgraph=None) -> UpdatePlan:
        """``view_draw`` with a new view: trace only, or rebuild the cascades when the view
        left their anchor cell (the cascades follow the view in whole coarse voxels)."""
        self.view_camera = camera
        state = None if self.staged is None else self.staged.state
        snapshot = self.snapshot or self.latest_snapshot
        reanchored = False
        if state is not None and snapshot is not None:
            moved = dataclasses.replace(snapshot, camera=camera)
            grids = cascade_grids(moved, self.staged.caches, gi_settings(_scene(self).voxgi))
            reanchored = not grids_equal(grids, state.grids)
        plan = view_plan(reanchored)
        if reanchored and self.pending is None:
            self.schedule(plan, scene or _scene(self), depsgraph)
        else:
            self._count(plan)
        return plan

    def image_source(self, quality: str):
        """(snapshot, GI state, version) the 3D view traces in ``quality``, or None while there
        is nothing to trace; a new version restarts the view's image. Accurate traces the
        scene's triangles, not the voxels: the latest snapshot taken (on the main thread, right
        after the change), without waiting for the worker (the state may be an older one, or
        None; Accurate does not read it). Fast cone-traces the worker's octree: the applied
        result."""
        if quality == "ACCURATE" and self.held_source is not None:
            return self.held_source  # a view finishes an earlier frame's first image first
        if quality == "ACCURATE" and self.latest_snapshot is not None:
            state = None if self.staged is None else self.staged.state
            return self.latest_snapshot, state, ("snapshot", self.snapshots)
        if self.staged is None or self.snapshot is None:
            return None
        return self.snapshot, self.staged.state, ("applied", self.generation)

    def _count(self, plan: UpdatePlan) -> None:
        self.planned.count(plan)
        self.plans.append(plan)

    # ------------------------------------------------------------------ the job

    def schedule(self, plan: UpdatePlan, scene, depsgraph=None) -> jobs.Job | None:
        """Snapshot now (main thread) and submit the plan's work to the worker; a full
        snapshot whose meshes take longer than ``read_slice`` to read waits for them
        (``read_on``), its plan kept in ``reading``."""
        self._count(plan)
        if plan.stages == {"trace"}:
            return None
        if self.reading is not None:  # a full snapshot's reads are under way: it joins them
            self.reading = self.reading.merged(plan)
            return None
        return self._submit(plan, scene, depsgraph)

    def read_on(self, scene, depsgraph=None, snapshot: bool = True) -> bool:
        """Go on with a full snapshot's mesh reads for ``read_slice`` seconds (all of them
        without one); the call after the one that read the last (with no update between)
        takes the snapshot and submits its job: a slice, then the snapshot, each within a
        draw or a tick. True while that is still to come. snapshot False (a draw in
        Blender's UI, where data may not be written: a snapshot writes temporary modifiers,
        images, bakes) leaves the snapshot to the timer (``tick``)."""
        if self.reading is None:
            return False
        depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
        if not self.read_all:
            self.read_all = self._read_ahead(depsgraph)
            if self.read_slice is not None:
                return True
        if not snapshot:
            start_ticking()
            return True
        plan, self.reading, self.read_all = self.reading, None, False
        self._submit(plan, scene, depsgraph, read=True)
        return False

    def bake_on(self, seconds: float, scene, depsgraph) -> bool:
        """A tick of the queued bakes (``bakes.BakeQueue.step``, about ``seconds``): what the
        child processes baked collected, the next bakes sent to one, or a slice of one baked
        here; False when nothing ran (none queued, a full snapshot's reads under way, nothing
        came in). A world whose map came in, and when the last material is
        baked the materials that were baked, are read again: an update whose snapshot (its
        meshes' reads kept) the next tick takes (``read_on``). Main thread, where Blender lets
        Python write data — a timer (``tick``), never ``view_draw``."""
        if not self.bakes.pending or self.reading is not None:
            return False
        if not self.bakes.step(seconds, depsgraph):
            return False
        worlds = self.bakes.worlds.finished
        records = [UpdateRecord("WORLD", name, False, False, True, "") for name in sorted(worlds)]
        worlds.clear()
        if records:
            self.world_changed = True  # the posed snapshot reads the world again
        if not self.bakes.requests:
            records += [UpdateRecord("MATERIAL", name, False, False, True, "")
                        for name in sorted(self.bakes.finished)]
            self.bakes.finished.clear()
        plan = plan_updates(records, self.index) if self.index is not None and records \
            else None
        if plan is not None and not plan.empty:  # the next tick takes the snapshot
            self._count(plan)
            self.reading, self.read_all = plan, False
        return True

    def _read_ahead(self, depsgraph) -> bool:
        """``read_ahead`` for ``read_slice`` (everything without one); True when every mesh
        is read. A read that fails forgets the kept reads and leaves the meshes to the
        snapshot, which reads them or says why it cannot."""
        try:
            return read_ahead(depsgraph, self.mesh_reads, self.read_slice or float("inf"))
        except Exception:  # noqa: BLE001 - never stuck between draws
            traceback.print_exc()
            self.mesh_reads.clear()
            return True

    def _submit(self, plan: UpdatePlan, scene, depsgraph=None, read: bool = False
                ) -> jobs.Job | None:
        """``schedule``'s snapshot and job; read : the meshes were just read ahead."""
        # what changed since the last snapshot decides how this one is read; the running job
        # it supersedes read what its own plan needed into that last snapshot (a pose played
        # while the first update still voxelizes reads the pose, not every mesh again)
        changed = plan
        running = jobs.running_job(self.scene_name)
        if running is not None and self.pending is not None:
            plan = self.pending.merged(plan)  # the superseded job's work still has to happen
        depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
        snapshot = None
        if not changed.full_snapshot and "snapshot" in changed.stages and \
                self.latest_snapshot is not None:
            # a pose or a move: matrices only, the world only when it changed
            # (docs/gi_pipeline.md "Posed updates")
            snapshot = transform_snapshot(self.latest_snapshot, scene, depsgraph,
                                          world=self.world_changed, bakes=self.bakes)
        elif "snapshot" not in changed.stages and self.latest_snapshot is not None:
            snapshot = self.latest_snapshot
        elif self.read_slice is not None and not read and not self._read_ahead(depsgraph):
            self.reading = plan  # the draws go on with the reads (``read_on``)
            return None
        try:
            if snapshot is None:
                snapshot, _ = snapshot_or_error(None, depsgraph, reads=self.mesh_reads,
                                                allow_empty=True, bakes=self.bakes)
        except VoxGIError as error:
            self.error = str(error)
            return None
        if not snapshot.objects:
            # a view layer that shows no mesh: the view shows its world alone, as Cycles' and
            # F12 do (render/viewport_world.py); nothing is voxelized, and what was taken
            # before (meshes since deleted or hidden) is traced no more
            self.world_only, self.latest_snapshot, self.index = snapshot, None, None
            self.error = ""
            return None
        self.world_only = None
        waits = ()
        if self.bakes.pending:
            start_ticking()
        if snapshot is not self.latest_snapshot:
            self.snapshots += 1
            waits = announce_snapshot(self, snapshot, scene)
        self.latest_snapshot = snapshot
        self.world, self.world_changed = world_state(scene), False
        self.skin = skin_states(snapshot, depsgraph)
        # a full snapshot's index was just taken by ``remember`` (snapshot_or_error)
        self.index = remembered_index(scene, snapshot) or scene_index(snapshot,
                                                                      depsgraph.view_layer)
        if self.view_camera is not None:
            snapshot = dataclasses.replace(snapshot, camera=self.view_camera)
        settings = scene.voxgi
        base_span, count, gi = settings.base_span, settings.cascade_count, gi_settings(settings)
        store, previous, progress = self.store, self.staged, self.progress
        bounce_cache = self.bounce_cache
        # the octree's GPU layout only for Fast, whose cones read it (Accurate traces the
        # triangles; a view switched to Fast lays out the applied octree itself: GPUVolume)
        fast = settings.quality != "ACCURATE"
        stages = plan.stages
        progress(0.0, "starting")

        def job(cancel):  # worker thread: engine code on plain data only
            wait_for(waits, cancel)  # the view's own preparation of the snapshot goes first
            t0 = time.perf_counter()
            refreshed = refresh_caches(store, snapshot, base_span, count, cancel,
                                       lambda f, text: progress(0.6 * f, text))
            t1 = time.perf_counter()
            staged = update_gi_stages(snapshot, refreshed.caches, gi, previous, stages, cancel,
                                      lambda f, text: progress(0.6 + 0.3 * f, text))
            t2 = time.perf_counter()
            atlas = None
            if fast:
                progress(0.9, "octree layout for the GPU")
                atlas = volume_atlas(staged.state.octree)
            t3 = time.perf_counter()
            bounced = None
            if bounce_cache is not None:  # Fast's cones: the octrees with the cache's bounces
                progress(0.95, "voxels with the radiance cache's bounces")
                bounced = bounced_volumes(staged.state, bounce_cache)
            t4 = time.perf_counter()
            progress(1.0, "done")
            timings = {"caches": t1 - t0, **{f"  {k}": v for k, v in refreshed.caches.timings.items()},
                       "gi": t2 - t1, **{f"  {k}": v for k, v in staged.state.timings.items()}}
            if atlas is not None:
                timings["atlas"] = t3 - t2
            if bounced is not None:
                timings["bounced octrees + atlases"] = t4 - t3
            return LiveResult(snapshot, refreshed.caches, staged, atlas, refreshed.voxelized,
                              refreshed.reused, timings, bounced)

        # A running job that voxelizes nothing is left to finish (the frames of a playing
        # animation, a drag): its image is shown and only the newest change waits after it.
        short = all(p is not None and not p.full_snapshot and not p.stages & {"voxelize", "albedo"}
                    for p in (plan, self.pending))
        self.pending = plan
        return jobs.submit(self.scene_name, job, label=JOB_LABEL,
                           on_done=lambda result: self._apply(plan, result),
                           on_cancel=self._cancelled, on_error=self._failed,
                           progress=progress, finish_running=short)

    def _apply(self, plan: UpdatePlan, result: LiveResult) -> None:
        if self.pending is plan:  # else a newer job is still to come
            self.pending = None
        self.snapshot, self.staged, self.atlas = result.snapshot, result.staged, result.atlas
        self.bounced = result.bounced
        self.generation += 1
        self.error = ""
        state = result.staged.state
        octree = state.octree.stats()
        self.stats = LiveStats(
            plan.triggers, result.staged.stages, result.voxelized, result.timings,
            [(cv.grid.index, cv.grid.span, cv.voxel_count, _cascade_bytes(cv) / MEGABYTE)
             for cv in state.cascades],
            sum(s.nodes for s in octree), sum(s.bytes for s in octree) / MEGABYTE,
            result.caches.total_bytes / MEGABYTE)
        session = scene_session(self.scene_name)  # F12 and the other panels see them too
        session.caches, session.gi_state = result.caches, state
        session.snapshot_summary = snapshot_summary(result.snapshot)
        session.gi_timings = {k: v for k, v in result.timings.items() if not k.startswith(" ")}
        tag_3d_views()

    def _cancelled(self) -> None:
        self.pending = None
        self.error = ""
        tag_3d_views()

    def _failed(self, error: BaseException) -> None:
        self.pending = None
        if not isinstance(error, VoxGIError):
            traceback.print_exception(error)
        self.error = f"{type(error).__name__}: {error}" if not isinstance(error, VoxGIError) \
            else str(error)
        tag_3d_views()

    @property
    def running(self) -> jobs.Job | None:
        return jobs.running_job(self.scene_name)


# Functions called with (live, snapshot, scene) for every new snapshot ``LiveGI.schedule``
# takes, before it submits the update job: the 3D view prepares its GPU scene from it at once,
# on a thread of its own (render/viewport_prepare.py, docs/gi_pipeline.md "Entering Rendered
# mode"). A hook may return a ``threading.Event`` the update job waits for before it starts:
# on 2 cores the two would halve each other, and the view's image is what the user waits for.
SNAPSHOT_HOOKS: list = []
HOOK_WAIT = 10.0  # seconds an update job waits at most for the hooks' work


def announce_snapshot(live: LiveGI, snapshot, scene) -> list:
    """Hand a new snapshot to ``SNAPSHOT_HOOKS``; the events they returned. A hook that fails
    is reported and skipped."""
    waits = []
    for hook in list(SNAPSHOT_HOOKS):
        try:
            event = hook(live, snapshot, scene)
        except Exception:  # noqa: BLE001 - the update job must still be submitted
            traceback.print_exc()
            continue
        if event is not None:
            waits.append(event)
    return waits


def wait_for(events, cancel) -> None:
    """Worker: wait for ``events`` (``announce_snapshot``'s), at most ``HOOK_WAIT`` seconds in
    all, and no longer once the job is cancelled."""
    deadline = time.perf_counter() + HOOK_WAIT
    for event in events:
        while not event.wait(0.05):
            if cancel() or time.perf_counter() > deadline:
                return


def _cascade_bytes(cascade_voxels) -> int:
    return sum(getattr(cascade_voxels, name).nbytes for name in
               ("cells", "albedo", "normal", "specular", "count", "mesh_has_finer"))


def _mesh_data_name(object_name: str) -> str | None:
    obj = bpy.data.objects.get(object_name)
    return None if obj is None or obj.data is None else obj.data.name_full


def _shape_keys_mesh(key_name: str) -> str | None:
    key = bpy.data.shape_keys.get(key_name)
    user = None if key is None else key.user
    return user.name_full if isinstance(user, bpy.types.Mesh) else None


def _scene(live: LiveGI):
    return bpy.data.scenes.get(live.scene_name) or bpy.context.scene


_live: dict[str, LiveGI] = {}


def live_gi(scene_name: str) -> LiveGI:
    """The scene's ``LiveGI``, created on first use."""
    live = _live.get(scene_name)
    if live is None:
        live = _live[scene_name] = LiveGI(scene_name)
    return live


def peek_live_gi(scene_name: str) -> LiveGI | None:
    return _live.get(scene_name)


def current_state(scene_name: str):
    """The GI state the 3D view shows for a scene: the viewport's applied result, else the
    last ``voxgi.update`` / F12 one, else None."""
    live = _live.get(scene_name)
    if live is not None and live.staged is not None:
        return live.staged.state
    from .session import peek_session

    session = peek_session(scene_name)
    return None if session is None else session.gi_state


def tick() -> float | None:
    """The live viewport's timer (``bpy.app.timers``, main thread): what its draws must not do,
    for the scene the window shows — Blender forbids ``view_draw`` to write data (its function
    is not ``FUNC_ALLOW_WRITE``: a write raises "Writing to ID classes in this context is not
    allowed"). A full snapshot whose mesh reads the draws finished (``read_on``: temporary
    modifiers of skinned meshes, UDIM tiles' images, a world's bake), else a slice of the
    queued material bakes (``LiveGI.bake_on``). The next tick's delay, or None when nothing
    is left. Without an event loop (tests, benchmarks) the caller ticks as the timer would,
    and background mode's draws take their snapshots themselves (no UI, no such rule)."""
    scene = bpy.context.scene
    live = None if scene is None else _live.get(scene.name_full)
    if live is None:
        return None
    depsgraph = bpy.context.evaluated_depsgraph_get()
    if live.reading is not None:
        live.read_on(scene, depsgraph)
        tag_3d_views()
    elif live.bakes.pending:
        try:
            live.bake_on(BAKE_SLICE, scene, depsgraph)
        except Exception:  # noqa: BLE001 - a bug here must not stop the timer: the bakes go
            traceback.print_exc()
            live.bakes.clear()
    return TICK_INTERVAL if live.reading is not None or live.bakes.pending else None


def start_ticking() -> None:
    """Run ``tick`` from a timer (in Blender's UI; never registered in background mode, where
    no timer fires and one left registered at exit crashed the process)."""
    if not bpy.app.background and not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=TICK_INTERVAL)


def clear() -> None:
    """Forget every scene's viewport results (file load, unregister); their bakes in other
    processes are stopped."""
    for live in _live.values():
        live.bakes.clear()
    _live.clear()
    if not bpy.app.background and bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)


@bpy.app.handlers.persistent
def _clear_on_load(*_args) -> None:
    clear()


@bpy.app.handlers.persistent
def _rescan_after_undo(*_args) -> None:
    # Undo restores data under the same names; fingerprints find out what really changed.
    for live in _live.values():
        live.rescan = "undo / redo"


HANDLERS = (("load_post", _clear_on_load), ("undo_post", _rescan_after_undo),
            ("redo_post", _rescan_after_undo))
classes = ()


def register() -> None:
    add_handlers(HANDLERS)


def unregister() -> None:
    remove_handlers(HANDLERS)
    clear()

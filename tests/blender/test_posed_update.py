"""Posed updates (docs/gi_pipeline.md "Posed updates"): a pose is bone matrices. A pose, a
move or a frame of a playing animation reads no mesh, material or world again and places the
voxels a full snapshot places; an edit of a mesh, modifier, material or the objects still
reads them; playing a rig in the viewport changes nothing in the file and ends on the last
frame's result. Counted, not timed."""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import threading

import bpy
import numpy as np
import pytest
import rig_scenes
import scenes

TIMEOUT = 120.0
DETAIL = 0.5  # a ~2.8k-face character: the same rig, a quicker test


@pytest.fixture
def rig_room(voxgi):
    scene = bpy.context.scene
    built = rig_scenes.build_gltf_rig_room(scene, DETAIL)
    scene.voxgi.span_mode = "MANUAL"  # cascades anchored on the camera: comparable updates
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.125, 2, "32"
    return scene, built


def reads():
    return importlib.import_module("voxgi.blender.snapshot.reads").read_counts()


def read_since(before):
    now = reads()
    return {k: now[k] - before[k] for k in now}


def same(a, b, path="snapshot"):
    """Assert two snapshot values are equal: dataclasses field by field, arrays exactly."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            if f.name != "warnings":
                same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)) and not isinstance(a, str):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert np.array_equal(np.asarray(a), np.asarray(b)), path
    else:
        assert a == b, path


def same_state(a, b):
    """Two GI states' cascades (every voxel array) and injected light, exactly."""
    assert len(a.cascades) == len(b.cascades)
    for x, y in zip(a.cascades, b.cascades):
        for name in ("cells", "albedo", "normal", "specular", "count", "mesh_has_finer"):
            assert np.array_equal(getattr(x, name), getattr(y, name)), name
    for x, y in zip(a.radiance, b.radiance, strict=True):
        assert np.array_equal(x, y)


def fresh_snapshot(scene):
    take = importlib.import_module("voxgi.blender.snapshot.scene").take_snapshot
    return take(scene, bpy.context.evaluated_depsgraph_get())


def test_a_pose_reads_no_mesh_material_or_world_and_gives_the_voxels_of_a_full_snapshot(
        rig_room, session):
    from voxgi.blender.settings import gi_settings
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.voxgi_addon.gi.update import update_gi

    scene, built = rig_room
    results = session.scene_session(scene.name_full)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    bone = built["rig"].pose.bones["Forearm.L"]
    bone.rotation_mode = "XYZ"
    for turn in (0.3, -0.5, 0.4):
        bone.rotation_euler.x += turn
        built["rig"].location.x += 0.05  # the armature object moves too
        before = reads()
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        assert read_since(before) == {"meshes": 0, "materials": 0, "worlds": 0}
        state = results.gi_state
        assert state.placed_objects == (built["body"].name,)
        # the voxels whose shadow rays meet none of the character's cells keep their light
        assert 0 < state.radiance.relit < sum(state.voxel_counts) / 2
        assert state.radiance.marched > 0

        # a full snapshot of the same pose, and an update of it from nothing
        full = fresh_snapshot(scene)
        assert read_since(before)["meshes"] > 0 and read_since(before)["materials"] > 0
        posed, _ = snapshot_or_error(bpy.context, posed=True)
        same(posed, full)
        fresh = update_gi(full, results.caches, gi_settings(scene.voxgi))
        same_state(state, fresh)

    mesh = bpy.data.objects["Back Wall"].data  # a mesh edit reads the meshes again
    mesh.vertices[0].co.z += 0.2
    mesh.update()
    before = reads()
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert read_since(before)["meshes"] > 0


def test_a_pose_beside_an_emissive_panel_relights_only_what_the_character_shades(
        rig_room, session):
    """An emissive surface in the room (a glowing panel on the back wall) is a light like the
    lamps: a pose relights only the voxels whose shadow rays meet the character's cells, to
    the light a full update gives; moving the panel relights every voxel."""
    from voxgi.blender.settings import gi_settings
    from voxgi.voxgi_addon.gi.update import update_gi

    scene, built = rig_room
    panel = rig_scenes.add_glowing_panel(scene)
    results = session.scene_session(scene.name_full)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert results.gi_state.radiance.emission is not None  # the panel glows in the voxels
    bone = built["rig"].pose.bones["Forearm.L"]
    bone.rotation_mode = "XYZ"
    for turn in (0.3, -0.5):
        bone.rotation_euler.x += turn
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        state = results.gi_state
        assert 0 < state.radiance.relit < sum(state.voxel_counts) / 2
        fresh = update_gi(fresh_snapshot(scene), results.caches, gi_settings(scene.voxgi))
        same_state(state, fresh)
    panel.location.x += 0.4
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    state = results.gi_state
    assert state.radiance.relit == sum(state.voxel_counts)
    same_state(state, update_gi(fresh_snapshot(scene), results.caches, gi_settings(scene.voxgi)))


def _edits(built):
    """(what, edit, does it need the meshes read again) in the order they are made."""
    body, rig, lamp = built["body"], built["rig"], built["lamp"]
    skin = body.data.materials[0]
    bsdf = next(n for n in skin.node_tree.nodes if n.type == "BSDF_PRINCIPLED")

    def modifier():
        body.modifiers.new("Smooth", "SMOOTH").factor = 0.8

    def modifier_setting():
        body.modifiers["Smooth"].iterations = 4

    def vertices():
        wall = bpy.data.objects["Left Wall"].data
        wall.vertices[1].co.x += 0.1
        wall.update()

    def add():
        scenes.quad_object("Added Quad", size=0.5).location = (0.5, -1.0, 0.6)

    def delete():
        bpy.data.objects.remove(bpy.data.objects["Added Quad"])

    def relink():
        slot = bpy.data.objects["Floor"].material_slots[0]
        slot.link = "OBJECT"
        slot.material = scenes.principled("Object Floor", (0.2, 0.6, 0.3))

    def hide():
        bpy.data.objects["Right Wall"].hide_render = True

    def visibility():
        body.visible_shadow = False

    def group():
        tree = bpy.data.node_groups.new("Tint", "ShaderNodeTree")
        tree.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
        rgb = tree.nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = (0.9, 0.2, 0.2, 1.0)
        tree.links.new(rgb.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
        wall = bpy.data.objects["Back Wall"].data.materials[0]
        node = wall.node_tree.nodes.new("ShaderNodeGroup")
        node.node_tree = tree
        principled = next(n for n in wall.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
        wall.node_tree.links.new(node.outputs[0], principled.inputs["Base Color"])

    def group_edit():
        tree = bpy.data.node_groups["Tint"]
        next(n for n in tree.nodes if n.type == "RGB").outputs[0].default_value = \
            (0.1, 0.3, 0.9, 1.0)

    return [
        ("pose", lambda: setattr(rig.pose.bones["Thigh.L"], "rotation_mode", "XYZ") or
         setattr(rig.pose.bones["Thigh.L"], "rotation_euler", (0.5, 0.0, 0.0)), False),
        ("light", lambda: setattr(lamp.data, "energy", 300.0), False),
        ("light moved", lambda: setattr(lamp, "location", (0.4, -0.5, 2.2)), False),
        ("world", lambda: setattr(bpy.context.scene.world, "color", (0.1, 0.05, 0.0)), False),
        ("film", lambda: setattr(bpy.context.scene.render, "film_transparent", True), False),
        ("ray visibility", visibility, False),
        ("material colour", lambda: bsdf.inputs["Roughness"].__setattr__("default_value", 0.2),
         True),
        ("modifier added", modifier, True),
        ("modifier setting", modifier_setting, True),
        ("pose after the modifier", lambda: setattr(rig.pose.bones["Thigh.L"], "rotation_euler",
                                                    (-0.3, 0.0, 0.0)), False),
        ("mesh vertices", vertices, True),
        ("object added", add, True),
        ("object deleted", delete, True),
        ("slot relinked", relink, True),
        ("object hidden", hide, True),
        ("node group added", group, True),
        ("node group edited", group_edit, True),
    ]


def test_edits_read_what_they_change_and_every_snapshot_equals_a_full_one(rig_room):
    """After each edit the update's snapshot (``posed=True``: posed when nothing else changed)
    equals a full snapshot taken then; only mesh, modifier, material, node group and object
    edits read the meshes again."""
    from voxgi.blender.snapshot import snapshot_or_error

    scene, built = rig_room
    snapshot_or_error(bpy.context, posed=True)
    for what, edit, full in _edits(built):
        edit()
        before = reads()
        snapshot, _ = snapshot_or_error(bpy.context, posed=True)
        assert (read_since(before)["meshes"] > 0) == full, what
        same(snapshot, fresh_snapshot(scene), what)


def file_state() -> str:
    """A digest of the file's datablocks: every collection's names, each object's matrix,
    modifiers and pose, each mesh's size."""
    digest = hashlib.blake2b(digest_size=16)
    for name in ("objects", "meshes", "materials", "node_groups", "images", "scenes", "actions",
                 "armatures", "worlds", "lights", "cameras", "collections"):
        digest.update(repr(sorted(i.name_full for i in getattr(bpy.data, name))).encode())
    for obj in bpy.data.objects:
        digest.update(np.array(obj.matrix_world, np.float64).tobytes())
        digest.update(repr([(m.name, m.type, m.show_viewport) for m in obj.modifiers]).encode())
        if obj.pose is not None:
            digest.update(repr([tuple(b.rotation_euler) for b in obj.pose.bones]).encode())
    for mesh in bpy.data.meshes:
        digest.update(f"{len(mesh.vertices)}:{len(mesh.polygons)}:{len(mesh.attributes)}".encode())
    return digest.hexdigest()


def held_once(function):
    """(wrapper, release, entered): ``function`` whose first call waits (on the worker) until
    ``release`` is set, ``entered`` set when it began; later calls run at once."""
    release, entered = threading.Event(), threading.Event()

    def held(*args, **kwargs):
        if not entered.is_set():
            entered.set()
            assert release.wait(TIMEOUT)
        return function(*args, **kwargs)

    return held, release, entered


class Recorder:
    """The depsgraph's updates as the viewport's ``view_update`` gets them (a frame change
    runs ``frame_change_post`` instead of ``depsgraph_update_post``)."""

    def __init__(self, live):
        from voxgi.blender.updates import records_from_depsgraph

        self.live, self.records, self.read = live, [], records_from_depsgraph

    def __call__(self, scene, depsgraph):
        self.records.extend(self.read(depsgraph, self.live.index))

    def take(self):
        records, self.records = self.records, []
        return records


@contextlib.contextmanager
def recording(live, release):
    """A ``Recorder`` of ``live``'s updates on the depsgraph's and the frame's changes while
    the block runs; leaving it lets the held job go (``release``) and removes the handlers."""
    recorder = Recorder(live)
    handlers = (bpy.app.handlers.depsgraph_update_post, bpy.app.handlers.frame_change_post)
    for handler in handlers:
        handler.append(recorder)
    try:
        yield recorder
    finally:
        release.set()
        for handler in handlers:
            handler.remove(recorder)


def test_playing_a_rig_reads_only_poses_drops_frames_and_ends_on_the_last(
        rig_room, interactive, monkeypatch):
    """Ten frames of an animated rig handed to the viewport while the worker is still busy
    with the second (held until the last frame is handed over, as a slow machine would): no
    frame after the first full update reads a mesh, material or world; the running job is left
    to finish and at most one job waits behind it (a newer frame supersedes it), so only the
    second frame's and the last frame's results are applied; the file is unchanged; the last
    result is the last frame's, voxel for voxel the update of a full snapshot of it."""
    from voxgi.blender import viewport_session
    from voxgi.blender.settings import gi_settings
    from voxgi.blender.snapshot.skin import read_armature
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.gi.incremental import update_gi_stages

    # the worker busy with one frame while the others come
    held_first, release, entered = held_once(update_gi_stages)

    jobs = interactive
    scene, built = rig_room
    rig = built["rig"]
    rig_scenes.keyframe_walk(rig, frames=10, start=1)
    scene.frame_set(1)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    untouched = file_state()
    live = live_gi(scene.name_full)
    jobs.synchronous = True
    live.update(scene, depsgraph)  # the first update: a full snapshot, every cache
    jobs.synchronous = False
    assert live.staged is not None and live.error == ""
    monkeypatch.setattr(viewport_session, "update_gi_stages", held_first)
    runner = jobs._runner
    before, waiting, plans, generation = reads(), [], len(live.plans), live.generation
    submitted = []
    with recording(live, release) as recorder:
        for frame in range(2, 11):
            scene.frame_set(frame)
            plan = live.update(scene, bpy.context.evaluated_depsgraph_get(), recorder.take())
            assert not plan.full_snapshot and "transform" in plan.stages, plan
            assert live.latest_snapshot.frame == frame
            submitted.append(jobs.latest_job(scene.name_full))
            if frame == 2:  # the worker has begun the second frame before the third comes
                assert entered.wait(TIMEOUT)
            waiting.append(sum(1 for j in runner.pending if not j.superseded and not j.started))
            jobs.drain()
    assert jobs.wait_idle(TIMEOUT)
    jobs.drain()
    assert read_since(before) == {"meshes": 0, "materials": 0, "worlds": 0}
    assert max(waiting) <= 1  # latest wins: never a queue of frames
    assert len(live.plans) == plans + 9
    states = [j.state for j in submitted]
    assert states == ["done"] + ["cancelled"] * 7 + ["done"], states  # frames 3-9 dropped
    assert live.generation == generation + 2
    assert live.error == "" and live.pending is None
    assert live.snapshot.frame == 10 and live.snapshot is live.latest_snapshot
    pose = read_armature(rig, rig.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    same(live.snapshot.armatures[rig.name_full], pose)

    full = fresh_snapshot(scene)
    expected = update_gi_stages(full, live.staged.caches, gi_settings(scene.voxgi), None,
                                {"transform"}).state
    same_state(live.staged.state, expected)
    scene.frame_set(1)  # the file as it was at the first frame: nothing added or changed
    assert file_state() == untouched


def test_frames_played_while_the_first_update_voxelizes_read_only_their_poses(
        rig_room, interactive, monkeypatch):
    """Play pressed while the first update (every mesh read, every cache voxelized) still runs:
    each frame supersedes that job with its work merged in, but reads only its pose — the
    meshes were read into the snapshot the running job was given. The last frame's result is
    voxel for voxel the update of a full snapshot of it."""
    from voxgi.blender import viewport_session
    from voxgi.blender.settings import gi_settings
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.gi.incremental import update_gi_stages

    # the first update's voxelization takes its time
    held_first, release, entered = held_once(viewport_session.refresh_caches)

    jobs = interactive
    scene, built = rig_room
    rig_scenes.keyframe_walk(built["rig"], frames=4, start=1)
    scene.frame_set(1)
    monkeypatch.setattr(viewport_session, "refresh_caches", held_first)
    live = live_gi(scene.name_full)
    with recording(live, release) as recorder:
        first = live.update(scene, bpy.context.evaluated_depsgraph_get())
        assert first.full_snapshot and entered.wait(TIMEOUT)
        before = reads()
        for frame in (2, 3, 4):
            scene.frame_set(frame)
            live.update(scene, bpy.context.evaluated_depsgraph_get(), recorder.take())
            assert live.latest_snapshot.frame == frame
        assert read_since(before) == {"meshes": 0, "materials": 0, "worlds": 0}
        assert "voxelize" in live.pending.stages  # the first update's work still to come
    assert jobs.wait_idle(TIMEOUT)
    jobs.drain()
    assert live.error == "" and live.pending is None and live.snapshot.frame == 4
    expected = update_gi_stages(fresh_snapshot(scene), live.staged.caches,
                                gi_settings(scene.voxgi), None, {"transform"}).state
    same_state(live.staged.state, expected)


def test_a_short_job_finishes_and_only_the_newest_waiting_one_runs_after_it(interactive):
    """``finish_running``: the running job is applied, a job waiting behind it is superseded
    by a newer one, which runs next."""
    jobs = interactive
    release, applied = threading.Event(), []
    first = jobs.submit("Scene", lambda cancel: release.wait(TIMEOUT) and "first",
                        on_done=applied.append)
    while not first.started:
        release.wait(0.01)
    second = jobs.submit("Scene", lambda cancel: "second", on_done=applied.append,
                         finish_running=True)
    third = jobs.submit("Scene", lambda cancel: "third", on_done=applied.append,
                        finish_running=True)
    assert second.superseded and not first.superseded and not first.cancel_requested
    release.set()
    assert jobs.wait_idle(TIMEOUT)
    assert applied == ["first", "third"]
    assert (first.state, second.state, third.state) == ("done", "cancelled", "done")

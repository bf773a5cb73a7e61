"""The live viewport's snapshots read only the meshes whose geometry changed
(blender/snapshot/mesh_cache.py, docs/gi_pipeline.md "Snapshots that read only what changed").

A sequence of edits, each handed to the viewport's ``LiveGI`` as the depsgraph reports it: after
every one the viewport's snapshot equals a full snapshot taken from scratch, and the edit read
exactly the meshes it changed — a light, a move or a material none. Counted, not timed.
"""
from __future__ import annotations

import bmesh
import bpy
import numpy as np
import pytest
import scenes
from test_posed_update import Recorder, read_since, reads, same


def fresh_snapshot(scene):
    from voxgi.blender.snapshot.scene import take_snapshot

    return take_snapshot(scene, bpy.context.evaluated_depsgraph_get())


def _cube(name, location, material, size=0.3):
    h = size / 2
    corners = [(x, y, z) for z in (-h, h) for y in (-h, h) for x in (-h, h)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    obj = scenes.mesh_object(name, corners, faces)
    obj.location = location
    obj.data.materials.append(material)
    return obj


def _grid(name, location, material):
    """A subdivided quad with a UV map (for a Displace modifier and shape keys)."""
    n = 6
    xs = np.linspace(-0.3, 0.3, n)
    vertices = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i)
             for j in range(n - 1) for i in range(n - 1)]
    obj = scenes.mesh_object(name, vertices, faces)
    obj.location = location
    obj.data.uv_layers.new(name="UVMap")
    obj.data.materials.append(material)
    return obj


@pytest.fixture
def live_box(voxgi):
    """A Cornell box with more kinds of mesh: a Displace modifier driven by a texture, a mesh
    with shape keys, two UV maps, a collection instance, a mesh without faces (in no
    snapshot); its ``LiveGI`` after a first update."""
    from voxgi.blender.viewport_session import live_gi

    scene = bpy.context.scene
    built = scenes.build_test_cornell_box(scene)
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.1, 2, "32"
    white = bpy.data.materials["Test White"]
    displaced = _grid("Displaced", (0.0, 0.0, 1.0), white)
    modifier = displaced.modifiers.new("Displace", "DISPLACE")
    modifier.texture = bpy.data.textures.new("Clouds", "CLOUDS")
    modifier.strength = 0.1
    keyed = _grid("Keyed", (0.5, 0.5, 1.2), white)
    keyed.shape_key_add(name="Basis")
    key = keyed.shape_key_add(name="Lift")
    key.data[7].co.z += 0.2
    keyed.data.uv_layers.new(name="Second")
    _cube("Cube", (-0.5, -0.5, 0.3), white)
    scenes.mesh_object("Edges Only", [(0, 0, 0), (0.2, 0, 0)], edges=[(0, 1)])  # no faces
    group = bpy.data.collections.new("Props")
    prop = _cube("Prop", (0.0, 0.0, 0.0), white)
    scene.collection.objects.unlink(prop)
    group.objects.link(prop)
    instancer = bpy.data.objects.new("Prop Instance", None)
    instancer.instance_type, instancer.instance_collection = "COLLECTION", group
    instancer.location = (0.5, -0.5, 0.3)
    scene.collection.objects.link(instancer)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    live.update(scene, depsgraph)
    assert live.latest_snapshot is not None, live.error
    return scene, built, live


def _edit_mode_move(obj):
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        bm = bmesh.from_edit_mesh(obj.data)
        for vertex in bm.verts[:4]:
            vertex.co.z += 0.05
        bmesh.update_edit_mesh(obj.data)
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")


def _edits(scene, built):
    """(what, edit, meshes it reads) in the order they are made."""
    lamp, tall, box = built["light"], built["tall"], built["box"]
    white = bpy.data.materials["Test White"]
    bsdf = next(n for n in white.node_tree.nodes if n.type == "BSDF_PRINCIPLED")

    def vertices():
        mesh = bpy.data.objects["Cube"].data
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        mesh.vertices.foreach_set("co", co * 1.2)
        mesh.update()

    def add():
        _cube("Added", (0.4, 0.2, 1.5), white)

    def slot_index():
        box.data.polygons[0].material_index = 1
        box.data.update()

    def render_uv():
        bpy.data.objects["Keyed"].data.uv_layers["Second"].active_render = True

    return [
        ("light power", lambda: setattr(lamp.data, "energy", lamp.data.energy * 1.5), 0),
        ("light moved", lambda: setattr(lamp, "location", (0.1, 0.1, 1.6)), 0),
        ("object moved", lambda: setattr(tall, "location", tall.location + type(tall.location)(
            (0.05, 0.0, 0.0))), 0),
        ("material colour", lambda: bsdf.inputs["Base Color"].__setattr__(
            "default_value", (0.3, 0.6, 0.9, 1.0)), 0),
        ("material roughness", lambda: setattr(bsdf.inputs["Roughness"], "default_value", 0.2),
         0),
        ("mesh vertices (data)", vertices, 1),
        ("mesh in edit mode (bmesh)", lambda: _edit_mode_move(tall), 1),
        ("object added", add, 1),
        ("object deleted", lambda: bpy.data.objects.remove(bpy.data.objects["Added"]), 0),
        ("object hidden", lambda: setattr(bpy.data.objects["Cube"], "hide_render", True), 0),
        ("object shown", lambda: setattr(bpy.data.objects["Cube"], "hide_render", False), 1),
        ("face material index", slot_index, 1),
        # a texture may feed any modifier: every object with modifiers or shape keys is read
        ("modifier's texture", lambda: setattr(bpy.data.textures["Clouds"], "noise_scale", 0.6),
         2),
        ("modifier setting", lambda: setattr(bpy.data.objects["Displaced"].modifiers[0],
                                             "strength", 0.2), 1),
        ("shape key value", lambda: setattr(bpy.data.objects["Keyed"].data.shape_keys
                                            .key_blocks["Lift"], "value", 0.7), 1),
        ("render UV map", render_uv, 1),
        ("instanced mesh", lambda: bpy.data.objects["Prop"].data.vertices[0].co.__setitem__(
            2, -0.3) or bpy.data.objects["Prop"].data.update(), 1),
        ("world", lambda: setattr(scene.world, "color", (0.05, 0.05, 0.1)), 0),
    ]


def test_each_edit_reads_only_what_it_changed_and_equals_a_full_snapshot(live_box):
    scene, built, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    recorder = Recorder(live)
    bpy.app.handlers.depsgraph_update_post.append(recorder)
    try:
        for what, edit, meshes in _edits(scene, built):
            recorder.take()
            edit()
            bpy.context.view_layer.update()
            before = reads()
            records = recorder.take()
            live.update(scene, depsgraph, records)
            read = read_since(before)
            assert read["meshes"] == meshes, (what, read, records)
            snapshot = live.latest_snapshot
            recorder.take()  # a fresh snapshot's own updates are not the user's
            same(snapshot, fresh_snapshot(scene), what)
            assert snapshot.warnings == fresh_snapshot(scene).warnings, what
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(recorder)


def test_a_light_edit_reads_no_mesh_attribute(live_box, monkeypatch):
    """A lamp's power through ``view_update``: no mesh evaluated, no attribute read."""
    from voxgi.blender.snapshot import mesh as mesh_reads

    scene, built, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    calls = []
    for name in ("read_positions", "read_triangles", "read_corner_uvs", "read_corner_normals"):
        original = getattr(mesh_reads, name)
        monkeypatch.setattr(f"voxgi.blender.snapshot.scene.{name}",
                            lambda *a, _f=original, _n=name, **k: calls.append(_n) or _f(*a, **k))
    recorder = Recorder(live)
    bpy.app.handlers.depsgraph_update_post.append(recorder)
    try:
        for energy in (40.0, 90.0, 160.0):
            built["light"].data.energy = energy
            bpy.context.view_layer.update()
            before = reads()
            plan = live.update(scene, depsgraph, recorder.take())
            # the lights only: the faceless object is not taken for one shown every time
            assert "snapshot" in plan.stages and not plan.full_snapshot, plan.triggers
            assert read_since(before) == {"meshes": 0, "materials": 0, "worlds": 0}
        # a material edit reads the materials, and still no mesh
        white = bpy.data.materials["Test White"]
        next(n for n in white.node_tree.nodes if n.type == "BSDF_PRINCIPLED").inputs[
            "Roughness"].default_value = 0.9
        bpy.context.view_layer.update()
        before = reads()
        plan = live.update(scene, depsgraph, recorder.take())
        assert plan.full_snapshot and read_since(before)["materials"] > 0
        assert read_since(before)["meshes"] == 0
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(recorder)
    assert calls == []


def test_a_new_engine_reads_everything_again(live_box):
    """Edits made while no engine listened (out of Rendered mode) are not in any update: the
    first ``view_update`` of a new engine reads every mesh again."""
    from stand_in_engine import StandInEngine

    from voxgi.render.viewport import view_update

    scene, _, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.objects["Cube"].data
    mesh.vertices[0].co.x -= 0.1  # no view_update sees this
    mesh.update()
    bpy.context.view_layer.update()
    before = reads()
    view_update(StandInEngine(), None, depsgraph)
    assert read_since(before)["meshes"] >= len(live.latest_snapshot.meshes)
    same(live.latest_snapshot, fresh_snapshot(scene), "after a new engine")


def test_a_full_snapshot_read_a_mesh_a_slice_sees_the_edits_made_between_slices(live_box):
    """Entering Rendered mode on a large scene: its meshes are read a slice per draw
    (``LiveGI.read_on``), and the job waits for them. An edit made between two slices to a
    mesh already read is read again; the snapshot then equals a full one, and the reads add
    up to one per mesh plus the edited one again."""
    scene, built, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    recorder = Recorder(live)
    bpy.app.handlers.depsgraph_update_post.append(recorder)
    try:
        taken, jobs_before = live.snapshots, len(live.plans)
        live.read_slice = 1e-9  # one mesh a slice
        live.rescan = "Rendered mode entered"
        before = reads()
        live.update(scene, depsgraph, recorder.take())
        assert live.reading is not None and live.snapshots == taken  # no snapshot yet
        assert read_since(before)["meshes"] == 1
        slices, edited = 1, False
        while live.read_on(scene, depsgraph):
            slices += 1
            assert live.snapshots == taken
            if not edited:  # the box's vertices, after the box was read ahead (the first)
                edited = True
                mesh = built["box"].data
                co = np.empty(len(mesh.vertices) * 3, np.float32)
                mesh.vertices.foreach_get("co", co)
                mesh.vertices.foreach_set("co", co * 0.8)
                mesh.update()
                bpy.context.view_layer.update()
                live.update(scene, depsgraph, recorder.take())  # joins the reads under way
                assert live.reading is not None and len(live.plans) == jobs_before + 2
        assert live.reading is None and live.snapshots == taken + 1
        # a mesh a slice: every mesh once (the faceless one too, in no snapshot), the edited
        # box again; the snapshot itself reads only what is never kept (the instanced mesh)
        assert slices >= len(live.latest_snapshot.meshes)
        assert read_since(before)["meshes"] == len(live.latest_snapshot.meshes) + 2
        recorder.take()
        same(live.latest_snapshot, fresh_snapshot(scene), "read a slice at a time")
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(recorder)


def test_a_read_ahead_that_fails_leaves_the_meshes_to_the_snapshot(live_box, monkeypatch,
                                                                    capsys):
    """A slice's read that raises (an object gone under it, a bug) never leaves the view
    waiting between draws: the kept reads are forgotten and the snapshot reads the meshes."""
    from voxgi.blender import viewport_session

    scene, _, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    original, calls = viewport_session.read_ahead, []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("a read went wrong")
        return original(*args, **kwargs)

    monkeypatch.setattr(viewport_session, "read_ahead", failing)
    taken = live.snapshots
    live.read_slice = 1e-9
    live.rescan = "Rendered mode entered"
    live.update(scene, depsgraph, [])
    assert live.reading is not None
    slices = 1
    while live.read_on(scene, depsgraph):
        slices += 1
    # view_update's slice, the failed one that ends the reads; the snapshot on the call after
    assert slices == 2 and len(calls) == 2
    assert "a read went wrong" in capsys.readouterr().err
    assert live.reading is None and live.snapshots == taken + 1 and live.error == ""
    same(live.latest_snapshot, fresh_snapshot(scene), "after a failed read")


def test_in_blenders_ui_the_draws_read_and_the_timer_takes_the_snapshot(live_box, monkeypatch):
    """Blender forbids ``view_draw`` to write data, and a snapshot writes (a skinned mesh's
    temporary modifier, UDIM tiles' images, a world's bake): in the UI the draws only read
    the meshes a slice each, and the viewport's timer (``viewport_session.tick``) takes the
    snapshot once they are read — the same snapshot as a full one."""
    from voxgi.blender import viewport_session

    scene, _, live = live_box
    depsgraph = bpy.context.evaluated_depsgraph_get()
    taken = live.snapshots
    live.read_slice = 1e-9
    live.rescan = "Rendered mode entered"
    live.update(scene, depsgraph, [])
    assert live.reading is not None
    for _ in range(100):  # the draws (``draw_view`` in the UI: snapshot=False)
        assert live.read_on(scene, depsgraph, snapshot=False)
        if live.read_all:
            break
    assert live.read_all and live.reading is not None and live.snapshots == taken
    assert live.read_on(scene, depsgraph, snapshot=False) and live.snapshots == taken  # still
    assert viewport_session.tick() is None  # the timer: the snapshot, nothing left to tick
    assert live.reading is None and live.snapshots == taken + 1
    same(live.latest_snapshot, fresh_snapshot(scene), "taken by the timer")

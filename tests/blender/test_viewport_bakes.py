"""The live viewport never holds Blender's main thread for a material bake: its snapshots queue
the bakes (the socket's value shown meanwhile) and its draws bake them a run of texel blocks
at a time (blender/snapshot/bakes.py; docs/gi_pipeline.md "Bakes a slice at a time")."""
from __future__ import annotations

import bpy
import numpy as np
from stand_in_engine import StandInEngine
from test_viewport import camera_matrices, cornell, engine_view, f12_combined, gpu_ready, relative_l1


def _uv_sphere_with(build_color):
    """(object, material) a UV sphere whose Principled Base Color is ``build_color(tree)``'s
    output socket."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    obj = bpy.context.object
    material = bpy.data.materials.new("Bake Me")
    tree = material.node_tree
    tree.links.new(build_color(tree), tree.nodes["Principled BSDF"].inputs["Base Color"])
    obj.data.materials.append(material)
    return obj, material


def _spec(obj, material, whole: bool = False):
    """(spec, corners, whole bake or None): the Base Color bake of ``material`` over ``obj``'s
    evaluated mesh as a snapshot reads it (``materials._bake_spec``), and with ``whole`` the
    socket baked whole, F12's way (``materials.bake_socket``)."""
    from voxgi.blender.snapshot import materials as snapshot_materials

    depsgraph = bpy.context.evaluated_depsgraph_get()
    obj_eval = obj.evaluated_get(depsgraph)
    mesh = obj_eval.to_mesh()
    try:
        surface = snapshot_materials.Surface(obj.name, obj_eval, mesh, [material], obj.name, True)
        baked = snapshot_materials.bake_socket(material, "DIFFUSE", "Base Color", surface) \
            if whole else None
        spec = snapshot_materials._bake_spec(material, "DIFFUSE", "Base Color", surface, False)
        return spec, len(mesh.loops), baked
    finally:
        obj_eval.to_mesh_clear()


def _whole_and_queued(obj, material):
    """The socket baked whole (F12's way) and through a queue a block a step (the viewport's
    way): (whole, queued, steps, blocks baked per step)."""
    from voxgi.blender.snapshot import bakes

    spec, loops, whole = _spec(obj, material, whole=True)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    stored = []
    queue = bakes.BakeQueue()
    queue.want("sphere", lambda: bakes.BakeRequest(spec, obj.name, loops, stored.append))
    queue.local.add("sphere")  # baked here, a run of blocks a step (not in a child)
    per_step, steps = [], 0
    while queue.pending:
        before = None if queue.requests["sphere"].todo is None else \
            int(queue.requests["sphere"].todo.sum())
        queue.step(0.0, depsgraph)  # no time at all: one run of one block
        steps += 1
        request = queue.requests.get("sphere")
        after = 0 if request is None else int(request.todo.sum())
        if before is not None:
            per_step.append(before - after)
    assert queue.failed == {} and queue.finished == {material.name_full} and len(stored) == 1
    return whole, stored[0], steps, per_step


def test_a_bake_a_block_at_a_time_is_the_whole_bake_texel_for_texel(voxgi):
    from voxgi.blender.snapshot import bakes

    # The UV coordinates as the colour: any shift of a run against the whole image shows.
    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    whole, queued, steps, per_step = _whole_and_queued(obj, material)
    covered = whole.sum(-1) > 0
    assert covered.mean() > 0.9 and np.array_equal(covered, queued.sum(-1) > 0)
    # within a texel's own spread of UVs (its samples are jittered over it)
    assert np.abs(queued - whole)[..., :2].max() < 1.5 / bakes.BAKE_SIZE
    assert set(per_step) == {1}  # a step with no time bakes one block, never more
    side = bakes.BAKE_SIZE // bakes.BLOCK
    assert steps <= side * side

    # Hard edges inside blocks and across their borders: the same image up to sampling noise.
    def checker(tree):
        node = tree.nodes.new("ShaderNodeTexChecker")
        node.inputs["Scale"].default_value = 13.0
        node.inputs["Color1"].default_value = (0.9, 0.1, 0.1, 1.0)
        node.inputs["Color2"].default_value = (0.1, 0.1, 0.9, 1.0)
        return node.outputs["Color"]

    obj, material = _uv_sphere_with(checker)
    whole, queued, _, _ = _whole_and_queued(obj, material)
    assert np.abs(queued - whole).mean() < 0.01
    assert abs(float(queued.mean()) - float(whole.mean())) < 1e-3


def test_a_childs_bake_is_the_whole_bake_and_an_image_only_in_memory_is_baked_here(voxgi):
    from voxgi.blender.snapshot import bakes

    def queued_and_whole(obj, material):
        spec, loops, whole = _spec(obj, material, whole=True)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        stored, queue = [], bakes.BakeQueue()
        queue.want("s", lambda: bakes.BakeRequest(spec, obj.name, loops, stored.append))
        queue.step(0.02, depsgraph)
        sent = queue.child is not None
        _drained(queue, depsgraph)
        assert queue.finished == {material.name_full} and len(stored) == 1
        return whole, stored[0], sent, queue

    def noisy(tree):  # a procedural colour with hard edges, in object space and by UV, and
        # the object's Random (the child's bake object is named for it: bakes.same_random_name)
        checker = tree.nodes.new("ShaderNodeTexChecker")
        checker.inputs["Scale"].default_value = 9.0
        noise = tree.nodes.new("ShaderNodeTexNoise")
        mix = tree.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        by_random = tree.nodes.new("ShaderNodeMath")
        by_random.operation = "MULTIPLY"
        tree.links.new(noise.outputs["Fac"], by_random.inputs[0])
        tree.links.new(tree.nodes.new("ShaderNodeObjectInfo").outputs["Random"], by_random.inputs[1])
        tree.links.new(by_random.outputs[0], mix.inputs["Factor"])
        tree.links.new(checker.outputs["Color"], mix.inputs[6])
        return mix.outputs[2]

    obj, material = _uv_sphere_with(noisy)
    whole, queued, sent, queue = queued_and_whole(obj, material)
    assert sent and not queue.local
    print(f"child against whole: largest texel difference {np.abs(queued - whole).max():.2e}")
    assert np.array_equal(queued, whole)  # the same Cycles bake of the same copy, elsewhere

    # an image painted in this session, never saved: the child could not see it
    def painted(tree):
        image = bpy.data.images.new("Painted", 16, 16)
        image.pixels.foreach_set(np.tile([0.9, 0.2, 0.1, 1.0], 256).astype(np.float32))
        node = tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        gamma = tree.nodes.new("ShaderNodeGamma")  # (a socket Cycles must bake)
        tree.links.new(node.outputs["Color"], gamma.inputs["Color"])
        return gamma.outputs["Color"]

    obj, material = _uv_sphere_with(painted)
    whole, queued, sent, queue = queued_and_whole(obj, material)
    assert not sent and queue.local == set()  # baked here, a run of blocks a step
    covered = whole.sum(-1) > 0
    assert np.abs(queued - whole)[covered].mean() < 0.01


def test_the_viewport_shows_the_value_then_a_child_bakes_it_and_f12_reuses_its_bake(
        voxgi, tmp_path):
    from voxgi.blender.snapshot.materials import bake_count
    from voxgi.blender.viewport_session import live_gi, tick

    scene = cornell()
    scene.voxgi_viewport.resolution_fraction = 1.0
    # the short block painted with a procedural checker (Generated coordinates, no UV map: the
    # bake lays its polygons out itself)
    material = bpy.data.materials.new("Test Checker")
    tree = material.node_tree
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.9, 0.6, 0.05, 1.0)
    checker.inputs["Color2"].default_value = (0.05, 0.2, 0.9, 1.0)
    tree.links.new(checker.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    block = bpy.data.objects["Short Block"]
    block.data.materials.clear()
    block.data.materials.append(material)
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    live = live_gi(scene.name_full)
    bakes = bake_count()

    live.update(scene, depsgraph)  # view_update: the snapshot queues the bake, runs none
    assert bake_count() == bakes and live.bakes.pending == 1
    plain = next(m for m in live.latest_snapshot.materials if m.name == "Test Checker")
    assert plain.base_color_texture < 0

    engine = StandInEngine()

    def converged():
        for _ in range(400):
            redraws = engine.redraws
            image = engine_view(engine, scene, depsgraph, view, window)
            if engine.redraws == redraws:
                return image
        raise AssertionError("the view never converged")

    first = converged()  # the view with the value: it does not wait for the bake
    assert bake_count() == bakes  # a draw never bakes (Blender forbids view_draw to write)
    assert any("Baking 1 material texture" in line for line in engine.stats)
    import time

    started, ticks = time.monotonic(), 0
    while time.monotonic() - started < 120.0:  # the bakes' timer, the view drawn between
        delay = tick()
        ticks += 1
        engine_view(engine, scene, depsgraph, view, window)
        if delay is None:
            break
    assert not live.bakes.pending and live.bakes.failed == {}
    assert bake_count() == bakes + 1  # baked once, by a child process: nothing here
    assert not live.bakes.local and all(r.todo is None for r in live.bakes.requests.values())
    print(f"the child's bake came back after {ticks} ticks, {time.monotonic() - started:.1f} s")
    baked = next(m for m in live.latest_snapshot.materials if m.name == "Test Checker")
    assert baked.base_color_texture >= 0  # the tick after the last bake took the snapshot
    image = converged()

    f12 = f12_combined(scene, tmp_path)
    assert bake_count() == bakes + 1  # F12 reads the viewport's bake from the cache
    print(f"view against F12: before the bake {relative_l1(first[..., :3], f12):.4f}, after the "
          f"bake {relative_l1(image[..., :3], f12):.4f}")
    assert relative_l1(image[..., :3], f12) <= 0.02
    # the view's image before the bake showed the plain value: the checker came with it
    assert relative_l1(first[..., :3], f12) > 1.5 * relative_l1(image[..., :3], f12)


def test_a_queued_bake_waits_while_another_voxgi_thread_has_work(voxgi):
    """Blender's bake operator reads its context override without Python's lock: with
    another thread holding it, the process crashed. No queued bake starts while a VoxGI
    thread has work; an idle worker (waiting for its next task) does not hold it back."""
    import threading

    from voxgi.blender.snapshot import bakes

    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    spec, loops, _ = _spec(obj, material)
    queue = bakes.BakeQueue()
    queue.want("sphere", lambda: bakes.BakeRequest(spec, obj.name, loops, lambda _pixels: None))
    queue.local.add("sphere")  # baked here (a child runs no operator in this process)
    release, has_work = threading.Event(), [True]
    thread = threading.Thread(target=release.wait, name="VoxGI test worker", daemon=True)
    thread.voxgi_busy = lambda: has_work[0]
    thread.start()
    try:
        count = bakes.bake_count()
        assert bakes.busy_thread() == "VoxGI test worker"
        assert not queue.step(1.0, depsgraph)
        assert bakes.bake_count() == count and queue.requests["sphere"].todo is None
        # a bake for a child is written and sent meanwhile: no operator runs here for it
        queue.want("child", lambda: bakes.BakeRequest(spec, obj.name, loops, lambda _pixels: None))
        assert queue.step(1.0, depsgraph) and queue.child is not None
        assert list(queue.child.stems.values()) == ["child"] and bakes.bake_count() == count + 1
        has_work[0] = False  # waiting for its next task
        assert bakes.busy_thread() == "" and queue.step(0.0, depsgraph)
        assert bakes.bake_count() == count + 2 and queue.requests["sphere"].todo is not None
        queue.clear()  # (the child stopped)
    finally:
        release.set()
        thread.join(5.0)


def test_a_queued_bake_whose_object_or_material_is_deleted_is_dropped_quietly(voxgi):
    """Objects and materials deleted while their bakes wait: the bakes are dropped (the
    deletion's own update reads the scene again), nothing fails, nothing of the bake stays;
    an object whose mesh is no longer the one its snapshot read is said why."""
    from voxgi.blender.snapshot import bakes

    def queued(obj, material):
        spec, loops, _ = _spec(obj, material)
        return bakes.BakeRequest(spec, obj.name, loops, lambda _pixels: None)

    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    queue = bakes.BakeQueue()
    queue.want("object", lambda: queued(obj, material))
    queue.local.add("object")  # baked here: deleted between two runs of blocks
    assert queue.step(0.0, bpy.context.evaluated_depsgraph_get())  # a block baked
    bpy.data.objects.remove(obj)
    assert queue.step(0.0, bpy.context.evaluated_depsgraph_get())
    assert queue.pending == 0 and queue.failed == {} and queue.finished == set()

    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    queue.want("material", lambda: queued(obj, material))
    bpy.data.materials.remove(material)
    assert queue.step(0.0, bpy.context.evaluated_depsgraph_get())  # (not sent to a child)
    assert queue.pending == 0 and queue.failed == {} and queue.child is None
    # an object whose mesh is not the one the snapshot read: said, not tried again
    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    request = queued(obj, material)
    request.loops += 3
    queue.want("changed", lambda: request)
    assert queue.step(0.0, bpy.context.evaluated_depsgraph_get())
    assert queue.pending == 0 and "no longer has the mesh" in queue.failed["changed"]
    assert queue.child is None
    names = ("VoxGI Bake", "VoxGI Bake.001")
    assert not any(n in bpy.data.meshes or n in bpy.data.objects or n in bpy.data.scenes or
                   n in bpy.data.images for n in names)


def test_a_queued_bake_of_a_material_on_no_face_is_not_queued_again(voxgi):
    """A material in a slot no face uses (left on an object, as users leave them): its queued
    bake finds nothing to bake, and the next snapshot neither queues it again nor warns."""
    from voxgi.blender.snapshot.bakes import BakeQueue
    from voxgi.blender.snapshot.scene import take_snapshot

    obj, material = _uv_sphere_with(
        lambda tree: tree.nodes.new("ShaderNodeTexCoord").outputs["UV"])
    unused = bpy.data.materials.new("Unused Checker")
    tree = unused.node_tree
    tree.links.new(tree.nodes.new("ShaderNodeTexChecker").outputs["Color"],
                   tree.nodes["Principled BSDF"].inputs["Base Color"])
    obj.data.materials.append(unused)  # slot 1, on no face
    queue = BakeQueue()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    take_snapshot(bpy.context.scene, depsgraph, bakes=queue)
    assert queue.pending == 2
    _drained(queue, depsgraph)
    assert len(queue.empty) == 1 and queue.finished == {"Bake Me"} and queue.failed == {}
    snapshot = take_snapshot(bpy.context.scene, depsgraph, bakes=queue)
    assert queue.pending == 0 and not any("Unused" in w for w in snapshot.warnings)


def _drained(queue, depsgraph, seconds=120.0):
    """Step ``queue`` as the bakes' timer would until nothing is pending."""
    import time

    started = time.monotonic()
    while queue.pending and time.monotonic() - started < seconds:
        queue.step(0.02, depsgraph)
        time.sleep(0.01)
    assert not queue.pending, "the bakes never came back"


def _sky_scene():
    """A ground plane under a Sky Texture world (what an artist lights an exterior with)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    world = bpy.data.worlds.new("Test Sky")
    tree = world.node_tree
    sky = tree.nodes.new("ShaderNodeTexSky")
    background = tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)  # what stands in meanwhile
    tree.links.new(sky.outputs["Color"], background.inputs["Color"])
    scene.world = world
    return scene, world, sky


def _world_baked(live, seconds=120.0):
    """Tick as the bakes' timer would until the view's world bakes in other processes are in:
    the ticks that polled them."""
    import time

    from voxgi.blender.viewport_session import tick

    ticks, started = 0, time.monotonic()
    while live.bakes.worlds.pending and time.monotonic() - started < seconds:
        tick()
        ticks += 1
        time.sleep(0.01)
    assert not live.bakes.worlds.pending, "the world's bake never came back"
    while tick() is not None:  # the snapshot that reads it
        continue
    return ticks


def test_a_node_built_world_bakes_in_another_process_and_the_view_reads_it_after(voxgi):
    from voxgi.blender.snapshot import world_map
    from voxgi.blender.viewport_session import live_gi
    from voxgi.voxgi_addon.scene.changes import UpdateRecord

    scene, world, sky = _sky_scene()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    bakes = world_map.bake_count()
    live.update(scene, depsgraph)  # view_update: the world goes to a child, nothing bakes here
    assert world_map.bake_count() == bakes and live.bakes.worlds.pending == 1
    waiting = live.latest_snapshot.world
    assert np.allclose(waiting.radiance[0, 0], (0.2, 0.3, 0.4))  # the Background's colour
    from voxgi.render.viewport import ViewportRenderer, status_line

    line = status_line(ViewportRenderer(), scene, live)
    assert "Baking the world…" in line and "material texture" not in line
    ticks = _world_baked(live)
    assert world_map.bake_count() == bakes and live.bakes.worlds.failed == {}
    shown = live.latest_snapshot.world
    world_map.clear_cache()
    here = world_map.bake_world(world, shown.radiance.shape[0])  # F12's own bake of it
    print(f"the child's map came back after {ticks} ticks; the sky's mean {here.mean():.3f}")
    assert shown.radiance.shape == here.shape and np.array_equal(shown.radiance, here)

    # an edit: the view keeps the last map while the new one bakes; a newer edit stops the
    # child of the older one
    world_map.store(shown.key, shown.radiance, False, world.name_full)  # (the cache cleared above)
    keys = []
    for elevation in (0.3, 0.6):
        sky.sun_elevation = elevation
        depsgraph = bpy.context.evaluated_depsgraph_get()
        live.update(scene, depsgraph, [UpdateRecord("WORLD", world.name_full, shading=True)])
        while live.reading is not None:
            live.read_on(scene, depsgraph)
        keys.append(world_map.world_key(world))
        assert np.array_equal(live.latest_snapshot.world.radiance, shown.radiance)
    assert list(live.bakes.worlds.running) == [keys[-1]]
    _world_baked(live)
    assert world_map.bake_count() == bakes + 1  # (the comparison's bake above)
    edited = live.latest_snapshot.world
    assert edited.key == keys[-1] and not np.array_equal(edited.radiance, shown.radiance)


def test_a_world_a_child_cannot_see_is_baked_in_the_snapshot(voxgi):
    from voxgi.blender.snapshot import world_map
    from voxgi.blender.viewport_session import live_gi

    # Texture Coordinate › Object: the empty's place is in this session only
    scene, world, sky = _sky_scene()
    tree = world.node_tree
    empty = bpy.data.objects.new("Sky Frame", None)
    scene.collection.objects.link(empty)
    coordinates = tree.nodes.new("ShaderNodeTexCoord")
    coordinates.object = empty
    gradient = tree.nodes.new("ShaderNodeTexGradient")
    tree.links.new(coordinates.outputs["Object"], gradient.inputs["Vector"])
    tree.links.new(gradient.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    bakes = world_map.bake_count()
    live.update(scene, depsgraph)
    assert world_map.bake_count() == bakes + 1 and not live.bakes.worlds.pending
    assert not live.latest_snapshot.world.key.endswith((":pending", ":fallback"))


def test_a_world_whose_child_fails_is_baked_in_the_next_snapshot(voxgi, monkeypatch):
    import sys

    from voxgi.blender import child_process
    from voxgi.blender.snapshot import world_map
    from voxgi.blender.viewport_session import live_gi

    monkeypatch.setattr(child_process, "command", lambda *args, **kwargs: [
        sys.executable, "-c", "import sys; print('no Cycles here'); sys.exit(3)"])
    scene, world, _ = _sky_scene()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    bakes = world_map.bake_count()
    live.update(scene, depsgraph)
    assert live.bakes.worlds.pending == 1 and world_map.bake_count() == bakes
    _world_baked(live)
    (why,) = live.bakes.worlds.failed.values()
    assert "code 3" in why and "no Cycles here" in why
    # the tick after the child ended read the world again, and baked it there
    assert world_map.bake_count() == bakes + 1
    assert live.latest_snapshot.world.key == world_map.world_key(world)


def test_children_still_running_when_blender_exits_are_stopped_and_leave_nothing(
        voxgi, monkeypatch):
    import os
    import sys

    from voxgi.blender import child_process

    monkeypatch.setattr(child_process, "command", lambda *args, **kwargs: [
        sys.executable, "-c", "import time; print('baking', flush=True); time.sleep(120)"])
    directory = child_process.workspace("voxgi-test-child-")
    child = child_process.Child.start("blender.snapshot.bakes", [], directory)
    assert child.ended() is None and os.path.isdir(directory)
    child_process._stop_all()  # (what Python runs at exit)
    assert child.ended() is not None and not os.path.exists(directory)


def test_an_f12_that_cannot_bake_waits_for_the_world_a_child_bakes_ahead(voxgi):
    """F12 in Blender's UI renders on a job thread, where no bake runs: while the file is open
    a timer has a child bake its world ahead, and F12 waits for that map instead of lighting
    the scene with the Background's colour."""
    from voxgi.blender.snapshot import world_map, world_process

    scene, world, _ = _sky_scene()
    world_map.clear_cache()
    scene.world = None
    assert not world_process.bake_ahead(scene)  # no world
    scene.world = bpy.data.worlds.new("Plain")  # read from its nodes: nothing to bake
    assert not world_process.bake_ahead(scene)
    scene.world = world
    bakes = world_map.bake_count()
    assert world_process.bake_ahead(scene) and not world_process.bake_ahead(scene)  # once
    key = world_map.world_key(world)
    assert list(world_process.ahead.running) == [key]
    warnings = []
    data = world_map.read_world(world, warnings, bake=False)  # F12's thread: waits for it
    assert warnings == [] and data.key == key and world_map.bake_count() == bakes
    assert not world_process.ahead.running
    world_map.clear_cache()
    assert np.array_equal(data.radiance, world_map.bake_world(world, data.radiance.shape[0]))
    # with no child for it, F12 says why it lights the scene with the Background's colour
    warnings = []
    world_map.read_world(world, warnings, bake=False)
    assert any("cannot run here" in w for w in warnings)


def test_a_world_that_cannot_go_to_a_child_leaves_the_warm_up_timer_running(voxgi, monkeypatch):
    from voxgi.blender import child_process
    from voxgi.blender.snapshot import world_map, world_process

    def no_processes(*args, **kwargs):
        raise OSError("no processes here")

    monkeypatch.setattr(child_process.subprocess, "Popen", no_processes)
    scene, world, _ = _sky_scene()
    world_map.clear_cache()
    assert not world_process.bake_ahead(scene)  # said, not raised into the timer
    assert "no processes here" in world_process.ahead.failed[world_map.world_key(world)]
    assert not world_process.bake_ahead(scene)  # not tried again
    world_process.ahead.clear()


def test_a_child_whose_bakes_are_wanted_no_more_is_stopped_for_the_next(voxgi):
    """An edit while a child bakes: its bakes are wanted no more, so the child stops and the
    edit's bake does not wait for it."""
    import os

    from voxgi.blender.snapshot import bakes

    obj, material = _uv_sphere_with(lambda tree: tree.nodes.new("ShaderNodeTexNoise").outputs[1])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    spec, loops, _ = _spec(obj, material)
    queue = bakes.BakeQueue()
    queue.want("before", lambda: bakes.BakeRequest(spec, obj.name, loops, lambda _pixels: None))
    assert queue.step(0.02, depsgraph) and list(queue.child.stems.values()) == ["before"]
    first = queue.child.child
    queue.begin()  # the edit's snapshot wants another bake
    queue.want("after", lambda: bakes.BakeRequest(spec, obj.name, loops, lambda _pixels: None))
    queue.end()
    # the next tick stops the first child and sends the edit's bake to a new one
    assert queue.step(0.02, depsgraph) and list(queue.child.stems.values()) == ["after"]
    assert first.ended() is not None and not os.path.exists(first.directory)
    _drained(queue, depsgraph)
    assert queue.finished == {material.name_full}


def _f12_snapshot(scene, serve: bool = True, cancelled=lambda: False, depsgraph=None):
    """(snapshot, the main thread's timer ticks meanwhile): ``take_snapshot`` on another
    thread, as F12 in Blender's UI reads the scene on its render thread (``cancelled``: its
    ``RenderEngine.test_break``), while the main thread ticks the timer that serves its bakes
    (``bakes.render_bakes.serve``, as ``kernel_warmup`` does) unless ``serve`` is False."""
    import threading
    import time

    from voxgi.blender.snapshot.bakes import render_bakes
    from voxgi.blender.snapshot.scene import take_snapshot

    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    out = {}

    def render_job():
        try:
            with render_bakes.watching(cancelled):
                out["snapshot"] = take_snapshot(scene, depsgraph)
        except BaseException as error:  # noqa: BLE001 - raised on the test's thread
            out["error"] = error

    thread = threading.Thread(target=render_job, name="F12 render job")
    ticks = 0
    render_bakes.served = True
    try:
        thread.start()
        while thread.is_alive():
            if serve and render_bakes.serve():
                ticks += 1
            time.sleep(0.02)
    finally:
        thread.join()
        render_bakes.served = False
    if "error" in out:
        raise out["error"]
    return out["snapshot"], ticks


def test_an_f12_in_the_ui_has_its_material_bakes_made_by_a_child_for_the_main_thread(voxgi):
    """F12 in the UI renders on a job thread, where no bake may run and no data be written:
    its snapshot hands the bakes to the main thread's timer, which has a child bake them, and
    reads the scene again with them, instead of rendering the socket's plain value."""
    from voxgi.blender.snapshot import materials as snapshot_materials
    from voxgi.blender.snapshot.scene import take_snapshot

    def baked(snapshot):
        read = next(m for m in snapshot.materials if m.name == material.name)
        assert read.base_color_texture >= 0, snapshot.warnings
        return snapshot.textures[read.base_color_texture].pixels

    obj, material = _uv_sphere_with(lambda tree: tree.nodes.new("ShaderNodeTexNoise").outputs[1])
    here = baked(take_snapshot(bpy.context.scene))  # the main thread's snapshot bakes in place
    snapshot_materials.clear_bake_cache()
    bakes = snapshot_materials.bake_count()
    snapshot, ticks = _f12_snapshot(bpy.context.scene)
    assert not any("Bake Me" in w for w in snapshot.warnings), snapshot.warnings
    assert np.array_equal(baked(snapshot), here)  # the same bake, made in a child
    assert snapshot_materials.bake_count() == bakes + 1 and ticks >= 2
    print(f"F12's bake came in after {ticks} ticks of the main thread's timer")
    # the next F12 reads it from the cache: nothing asked of the main thread
    snapshot, ticks = _f12_snapshot(bpy.context.scene, serve=False)
    assert ticks == 0 and snapshot_materials.bake_count() == bakes + 1
    assert next(m for m in snapshot.materials if m.name == material.name).base_color_texture >= 0


def test_an_f12_whose_bakes_do_not_come_in_says_so_and_leaves_no_child(voxgi, monkeypatch):
    from voxgi.blender.snapshot import bakes
    from voxgi.blender.snapshot import materials as snapshot_materials

    obj, material = _uv_sphere_with(lambda tree: tree.nodes.new("ShaderNodeTexNoise").outputs[1])
    snapshot_materials.clear_bake_cache()
    # no main thread serving them (a timer that never runs): the render waits WAIT, then says
    monkeypatch.setattr(bakes.RenderBakes, "WAIT", 0.5)
    snapshot, _ = _f12_snapshot(bpy.context.scene, serve=False)
    read = next(m for m in snapshot.materials if m.name == material.name)
    assert read.base_color_texture < 0
    assert any("Bake Me" in w and "did not end in time" in w for w in snapshot.warnings), \
        snapshot.warnings
    assert bakes.render_bakes.serve() is False  # nothing left asked of the timer
    # Esc during the wait (RenderEngine.test_break): the render goes on at once, says why
    monkeypatch.setattr(bakes.RenderBakes, "WAIT", 600.0)
    import time

    started = time.monotonic()
    snapshot, _ = _f12_snapshot(bpy.context.scene, serve=False,
                                cancelled=lambda: time.monotonic() - started > 0.3)
    assert time.monotonic() - started < 60.0
    assert any("Bake Me" in w and "cancelled" in w for w in snapshot.warnings), snapshot.warnings

    # an image painted in this session and never saved: no child can see it, and no bake may
    # run beside a render job: said, the value used
    image = bpy.data.images.new("Painted", 16, 16)
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.links.new(node.outputs["Color"],
                                 material.node_tree.nodes["Noise Texture"].inputs["Scale"])
    monkeypatch.setattr(bakes.RenderBakes, "WAIT", 60.0)
    snapshot, _ = _f12_snapshot(bpy.context.scene)
    assert any("Bake Me" in w and "only in this session's memory" in w
               for w in snapshot.warnings), snapshot.warnings

    # with no timer to serve them (background mode, a script's thread) the old words stand
    snapshot_materials.clear_bake_cache()
    import threading

    from voxgi.blender.snapshot.scene import take_snapshot
    out = {}
    thread = threading.Thread(target=lambda: out.setdefault("s", take_snapshot(bpy.context.scene)))
    thread.start()
    thread.join()
    assert any("cannot run here" in w for w in out["s"].warnings), out["s"].warnings


def test_an_f12_in_the_ui_has_a_child_bake_the_world_of_its_frame(voxgi):
    """F12 in the UI at a frame whose node-built world no child baked ahead (a keyframed sky):
    the main thread's timer starts a child for it, with the render's own values, and the render
    waits for its map instead of lighting the scene with the Background's colour."""
    from voxgi.blender.snapshot import world_map, world_process

    scene, world, _ = _sky_scene()
    world_map.clear_cache()
    world_process.ahead.clear()
    strength = world.node_tree.nodes["Background"].inputs["Strength"]
    strength.default_value = 1.0
    strength.keyframe_insert("default_value", frame=1)
    strength.default_value = 3.0
    strength.keyframe_insert("default_value", frame=3)
    scene.frame_set(3)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    # the user's world moves on while the render's depsgraph keeps frame 3's values (as an
    # animation render's does while the UI stays on another frame)
    strength.default_value = 9.0
    bakes = world_map.bake_count()
    snapshot, ticks = _f12_snapshot(scene, depsgraph=depsgraph)
    assert not any("Test Sky" in w for w in snapshot.warnings), snapshot.warnings
    assert world_map.bake_count() == bakes and ticks >= 1  # baked by a child, nothing here
    assert not world_process.ahead.running
    evaluated = depsgraph.scene_eval.world
    assert evaluated.node_tree.nodes["Background"].inputs["Strength"].default_value == 3.0
    here = world_map.bake_world(evaluated, snapshot.world.radiance.shape[0])
    assert np.array_equal(snapshot.world.radiance, here)  # frame 3's sky, not the user's 9
    world_process.ahead.clear()

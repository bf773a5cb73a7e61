"""What the depsgraph renders (issue 18, point 1, in part): collection instances, curves and
text are drawn, a mesh used by many instances is read once, and objects disabled in renders are
left out, in the snapshot and in the preview beside Cycles."""
from __future__ import annotations

import bpy
import gi_scenes
import numpy as np
from cycles_reference import coverage_agreement, relative_l1, render_cycles_passes

WIDTH, HEIGHT = 96, 72


def build_open_room(scene):
    """A floor, a chair collection instanced three times, a bevelled curve, a text object and
    an 'outline' box disabled in renders; a sun."""
    grey = gi_scenes._material("Grey", (0.6, 0.6, 0.6))
    red = gi_scenes._material("Red", (0.8, 0.2, 0.1))
    gi_scenes._mesh(scene, "Floor", [(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)],
                    [(0, 1, 2, 3)], (grey,))
    chairs = bpy.data.collections.new("Chairs")
    chair = bpy.data.objects.new("Chair", bpy.data.meshes.new("Chair Mesh"))
    vertices, faces = gi_scenes._box((-0.3, -0.3, 0), (0.3, 0.3, 0.9))
    chair.data.from_pydata(vertices, [], faces)
    chair.data.materials.append(red)
    chairs.objects.link(chair)
    for i in range(3):
        instancer = bpy.data.objects.new(f"Chair Instance {i}", None)
        instancer.instance_type, instancer.instance_collection = "COLLECTION", chairs
        instancer.location = (1.3 * i - 1.3, 0.8, 0.0)
        instancer.rotation_euler.z = 0.3 * i
        scene.collection.objects.link(instancer)
    rail = bpy.data.curves.new("Rail", "CURVE")
    rail.dimensions, rail.bevel_depth = "3D", 0.06
    spline = rail.splines.new("POLY")
    spline.points.add(2)
    for k, co in enumerate([(-2.5, 1.8, 0.4, 1), (0.0, 2.2, 1.0, 1), (2.5, 1.8, 0.4, 1)]):
        spline.points[k].co = co
    rail_object = bpy.data.objects.new("Rail", rail)
    rail_object.data.materials.append(grey)
    scene.collection.objects.link(rail_object)
    text = bpy.data.curves.new("Sign", "FONT")
    text.body, text.extrude, text.size = "VOX", 0.08, 0.8
    sign = bpy.data.objects.new("Sign", text)
    sign.location, sign.rotation_euler = (-0.8, -1.2, 0.1), (1.3, 0.0, 0.0)
    scene.collection.objects.link(sign)
    outline = gi_scenes._block(scene, "Outline", (1.5, 1.5, 1.5), (0.0, 0.5, 0.0), 0.0, grey)
    outline.hide_render = True
    gi_scenes._light(scene, "Sun", "SUN", (0, 0, 8), direction=(0.3, 0.4, -0.85), energy=3.0)
    gi_scenes._camera(scene, "Camera", (0.0, -6.0, 3.0), (0.0, 0.5, 0.5), lens=32.0)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    gi_scenes._finish(scene, {})


def test_instances_curves_and_text_are_read_and_hidden_objects_are_not(voxgi):
    from voxgi.blender.snapshot import snapshot_or_error

    build_open_room(bpy.context.scene)
    snapshot, _ = snapshot_or_error(bpy.context)
    names = [o.name for o in snapshot.objects]
    chairs = [o for o in snapshot.objects if o.name.endswith("› Chair")]
    assert len(chairs) == 3 and {o.mesh for o in chairs} == {"Chair Mesh"}  # one mesh, read once
    assert len({tuple(o.world_matrix[:3, 3]) for o in chairs}) == 3
    assert "Rail" in names and "Sign" in names and "Outline" not in names
    assert len(snapshot.meshes["Rail"].triangles) > 20 and len(snapshot.meshes["Sign"].triangles) > 20


def test_the_preview_draws_what_cycles_draws(voxgi, tmp_path):
    scene = bpy.context.scene
    build_open_room(scene)
    scene.cycles.filter_width = 0.01  # point samples on both sides
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=WIDTH,
                                        resolution_y=HEIGHT) == {"FINISHED"}
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    ours = read_exr_passes(str(tmp_path / "p.exr"))
    cycles = render_cycles_passes(scene, WIDTH, HEIGHT, 4, filter_width=0.01)
    geometry = cycles["Alpha"] > 0.5
    assert coverage_agreement(ours["Diffuse Color"].sum(-1) > 0, cycles) > 0.98
    assert relative_l1(ours["Diffuse Color"], cycles["Diffuse Color"], geometry) < 0.03
    red = (cycles["Diffuse Color"][..., 0] > 0.6) & (cycles["Diffuse Color"][..., 1] < 0.3)
    assert red.sum() > 30 and (np.asarray(ours["Diffuse Color"])[red][:, 0] > 0.6).mean() > 0.95


def test_what_the_preview_leaves_out_is_said_once(voxgi, tmp_path):
    from voxgi.blender.session import scene_session

    scene = bpy.context.scene
    build_open_room(scene)
    glass = gi_scenes._material("Glass", (0.9, 0.9, 0.9))
    glass.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    pane = gi_scenes._mesh(scene, "Pane", [(-1, -2, 0), (1, -2, 0), (1, -2, 1), (-1, -2, 1)],
                           [(0, 1, 2, 3)], (glass,))
    pane.data.materials.append(glass)
    hair = bpy.data.objects.new("Hair", bpy.data.hair_curves.new("Hair"))
    scene.collection.objects.link(hair)
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=32,
                                        resolution_y=24) == {"FINISHED"}
    warnings = [line for level, line in scene_session(scene.name_full).last_report
                if level == "WARNING"]
    said = [w for w in warnings if "Glass" in w and "thin surface" in w]
    assert len(said) == 1
    assert any("Hair" in w and "hair curves" in w for w in warnings)

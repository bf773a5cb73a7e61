"""Small scene builders for the Blender tests (data API only, background-safe)."""
from __future__ import annotations

import bpy
import numpy as np


def mesh_object(name, vertices, faces=(), edges=(), scene=None, data_name=None):
    """A new mesh object from vertex (N, 3) and face index lists, linked into the scene."""
    from voxgi.blender.scene_building import mesh_object as build

    collection = (scene or bpy.context.scene).collection
    return build(name, vertices, faces, edges=edges, collection=collection, data_name=data_name)


def principled(name, color, roughness=0.5, metallic=0.0, specular=0.5,
               emission=(0.0, 0.0, 0.0), emission_strength=0.0):
    """A material with a Principled BSDF set to these values (linear RGB)."""
    from voxgi.blender.scene_building import principled_material

    return principled_material(name, color, roughness, metallic, specular, emission,
                               emission_strength)


def link(obj, scene=None):
    """Link ``obj`` into the scene's master collection and return it."""
    (scene or bpy.context.scene).collection.objects.link(obj)
    return obj


def quad_object(name="Quad", size=1.0, scene=None):
    """A single square face of edge ``size`` in the XY plane, centred on the origin."""
    h = size / 2
    return mesh_object(name, [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [(0, 1, 2, 3)], scene=scene)


def armature_object(name, bones, scene=None):
    """An armature object with ``bones``: (name, head, tail, parent name or None, deform) tuples."""
    from voxgi.blender.scene_building import BoneSpec, add_bones

    scene = scene or bpy.context.scene
    obj = link(bpy.data.objects.new(name, bpy.data.armatures.new(name)), scene)
    add_bones(scene, obj, [BoneSpec(*bone) for bone in bones])
    return obj


def assign_weights(obj, group_names, weights):
    """Create vertex groups ``group_names`` on ``obj`` with ``weights`` (V, G); zero = not in the group.

    One ``VertexGroup.add`` call per (group, distinct weight): no per-vertex loop.
    """
    weights = np.asarray(weights, dtype=np.float64)
    for g, name in enumerate(group_names):
        group = obj.vertex_groups.new(name=name)
        column = weights[:, g]
        for value in np.unique(column[column > 0]):
            group.add(np.nonzero(column == value)[0].tolist(), float(value), "REPLACE")


def skinned_strip(scene=None, weights=None, extra_groups=("ctrl", "not_a_bone")):
    """A 4-vertex strip skinned to an armature with 6 deform bones and one non-deform bone 'ctrl'.

    Returns (mesh object, armature object, group names, weights (4, 6 + len(extra_groups))).
    The deform bones are 'B0'..'B5' along +X; 'ctrl' does not deform.
    """
    bones = [(f"B{i}", (i, 0, 0), (i + 0.9, 0, 0), f"B{i - 1}" if i else None, True) for i in range(6)]
    bones.insert(3, ("ctrl", (0, 1, 0), (0, 1, 1), None, False))
    rig = armature_object("Rig", bones, scene)
    strip = mesh_object("Strip", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], scene=scene)
    names = [f"B{i}" for i in range(6)] + list(extra_groups)
    if weights is None:
        weights = np.array([
            [0.9, 0.5, 0.4, 0.3, 0.2, 0.1, 1.0, 1.0],   # 6 deform influences -> top 4 kept
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.7, 0.0],   # one influence -> weight 1
            [0.2, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9],   # two equal influences
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0],   # only non-deform groups -> all zero
        ])[:, : len(names)]
    assign_weights(strip, names, weights)
    modifier = strip.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    return strip, rig, names, weights


def expected_top4(weights, bone_count):
    """Reference top-4 normalised weights per vertex as a list of {bone index: weight} dicts."""
    out = []
    for row in np.asarray(weights, dtype=np.float64)[:, :bone_count]:
        order = np.argsort(-row, kind="stable")[:4]
        kept = {int(i): row[i] for i in order if row[i] > 0}
        total = sum(kept.values())
        out.append({i: w / total for i, w in kept.items()})
    return out


# --------------------------------------------------------------------------- lighting test scenes

def _black_world(scene):
    """A black world: Cycles' Diffuse Direct then holds the scene's lights only."""
    world = bpy.data.worlds.new("Black World")
    world.color = (0.0, 0.0, 0.0)
    background = world.node_tree and next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if background is not None:
        background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        background.inputs["Strength"].default_value = 0.0
    scene.world = world
    return world


def _box_faces(lo, hi):
    """Vertices and outward quads of the axis-aligned box [lo, hi]."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    vertices = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return vertices, faces


def _block(name, size, location, angle, material, scene):
    """A box of ``size`` (x, y, z) standing on z = location.z, turned ``angle`` radians about Z."""
    sx, sy, sz = size
    vertices, faces = _box_faces((-sx / 2, -sy / 2, 0.0), (sx / 2, sy / 2, sz))
    obj = mesh_object(name, vertices, faces, scene=scene)
    obj.data.materials.append(material)
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, angle)
    return obj


def _light(scene, name, kind, location, **settings):
    light = bpy.data.lights.new(name, kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = link(bpy.data.objects.new(name, light), scene)
    obj.location = location
    return obj


TEST_BOX_LIGHTS = {
    # kind: (location, settings) — lights shine down (local -Z) where it matters.
    "POINT": ((0.0, 0.0, 1.5), dict(energy=80.0, shadow_soft_size=0.05)),
    "AREA": ((0.0, 0.0, 1.95), dict(energy=120.0, size=0.6, shape="SQUARE")),
}


def build_test_cornell_box(scene, light="POINT"):
    """A 2 m Cornell box lit by one known light, seen through its open front by the scene camera.

    World space, Z up: the interior spans x, y in [-1, 1], z in [0, 2]; the front (-Y) is open.
    Floor, ceiling and back wall are white (0.8), the left wall (x = -1) red, the right wall
    (x = +1) green; a short and a tall white block cast shadows. ``light`` is 'POINT' (80 W at
    (0, 0, 1.5), radius 5 cm) or 'AREA' (120 W, 0.6 m square at z = 1.95 facing down); see
    ``TEST_BOX_LIGHTS``. The world is black, the camera (35 mm lens, 4:3) stands at
    (0, -3.4, 1) looking along +Y. Returns the created objects by role.
    """
    white = principled("Test White", (0.8, 0.8, 0.8))
    red = principled("Test Red", (0.8, 0.05, 0.05))
    green = principled("Test Green", (0.05, 0.8, 0.05))
    corners = [(x, y, z) for z in (0.0, 2.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]  # normals inwards
    box = mesh_object("Test Box", corners, faces, scene=scene)
    for material in (white, red, green):
        box.data.materials.append(material)
    box.data.polygons.foreach_set("material_index", np.array([0, 0, 0, 1, 2], dtype=np.int32))
    box.data.update()
    short = _block("Short Block", (0.6, 0.6, 0.6), (0.35, -0.3, 0.0), 0.3, white, scene)
    tall = _block("Tall Block", (0.6, 0.6, 1.2), (-0.4, 0.4, 0.0), -0.3, white, scene)
    location, settings = TEST_BOX_LIGHTS[light]
    lamp = _light(scene, f"Test {light.title()} Light", light, location, **settings)
    camera = link(bpy.data.objects.new("Test Camera", bpy.data.cameras.new("Test Camera")), scene)
    camera.location = (0.0, -3.4, 1.0)
    camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
    camera.data.lens = 35.0
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = 96, 72
    _black_world(scene)
    return {"box": box, "short": short, "tall": tall, "light": lamp, "camera": camera}


THIN_WALL_HALF_THICKNESS = 0.01  # metres: the wall at x = 0 spans x in [-0.01, 0.01]
THIN_WALL_VIEW = 4.2  # metres of x the orthographic camera sees (128 x 64 pixels -> 4.2 x 2.1 m)


def build_thin_wall_room(scene):
    """A closed room split in two by a 2 cm wall, lit on one side only, seen from above.

    The room is the closed box x in [-2, 2], y in [-1, 1], z in [0, 2] (white, normals inwards);
    the wall is a closed slab x in [-0.01, 0.01] reaching through floor, ceiling and side walls,
    so no ray passes from one half to the other. A 100 W point light hangs at (-1, 0, 1.5):
    x < 0 is the lit side, x > 0 the dark side, which gets no light at all in Cycles.

    The camera is orthographic, straight above at z = 3 looking down, with its near clipping
    plane at z = 1.95: camera rays start below the ceiling (Cycles clips planes, and so do
    ``raycast.camera_rays``), so one 2:1 image (128 x 64 by default) shows the floor of both
    halves while the ceiling still bounces light. Pixel column i sees
    x = -2.1 + (i + 0.5) · 4.2 / width; ``thin_wall_side_masks`` turns that into side masks.
    Returns the created objects by role.
    """
    white = principled("Room White", (0.8, 0.8, 0.8))
    vertices, faces = _box_faces((-2.0, -1.0, 0.0), (2.0, 1.0, 2.0))
    room = mesh_object("Room", vertices, [tuple(reversed(f)) for f in faces], scene=scene)
    room.data.materials.append(white)
    h = THIN_WALL_HALF_THICKNESS
    vertices, faces = _box_faces((-h, -1.001, -0.001), (h, 1.001, 2.001))
    wall = mesh_object("Thin Wall", vertices, faces, scene=scene)
    wall.data.materials.append(white)
    lamp = _light(scene, "Room Light", "POINT", (-1.0, 0.0, 1.5), energy=100.0, shadow_soft_size=0.05)
    camera_data = bpy.data.cameras.new("Room Camera")
    camera_data.type = "ORTHO"
    camera_data.ortho_scale = THIN_WALL_VIEW
    camera_data.clip_start = 1.05
    camera_data.clip_end = 10.0
    camera = link(bpy.data.objects.new("Room Camera", camera_data), scene)
    camera.location = (0.0, 0.0, 3.0)
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = 128, 64
    _black_world(scene)
    return {"room": room, "wall": wall, "light": lamp, "camera": camera}


def thin_wall_side_masks(width=128, height=64, margin=0.15):
    """(lit, dark) (H, W) bool masks of ``build_thin_wall_room``'s image: floor pixels whose x is
    more than ``margin`` metres from the wall on the lit (x < 0) or the dark (x > 0) side, and
    more than ``margin`` inside the room's walls."""
    x = -THIN_WALL_VIEW / 2 + (np.arange(width) + 0.5) * THIN_WALL_VIEW / width
    y = THIN_WALL_VIEW / width * height / 2 - (np.arange(height) + 0.5) * THIN_WALL_VIEW / width
    gx, gy = np.meshgrid(x, y)
    inside = (np.abs(gx) < 2.0 - margin) & (np.abs(gy) < 1.0 - margin)
    return inside & (gx < -margin), inside & (gx > margin)


def camera_looking_at(location, target=(0.0, 0.0, 0.0), scene=None):
    """A new scene camera at ``location`` looking at ``target`` (up: +Z)."""
    from mathutils import Vector

    scene = scene or bpy.context.scene
    camera = link(bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera")), scene)
    camera.location = location
    camera.rotation_euler = (Vector(target) - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = camera
    return camera


def uniform_world(colour, scene=None, name="World"):
    """A new world of one Background colour (RGB), the scene's."""
    scene = scene or bpy.context.scene
    world = bpy.data.worlds.new(name)
    next(n for n in world.node_tree.nodes if n.type == "BACKGROUND").inputs[
        "Color"].default_value = (*colour, 1.0)
    scene.world = world
    return world

"""Four GI scenes nobody tuned VoxGI for (bpy data API, deterministic, background-safe).

Each builder fills an empty scene with geometry, Principled materials left at Blender's
defaults except the base colour (roughness 0.5, specular IOR level 0.5), lights, a black world
and a 160 × 120 camera; they differ in scale, light types and the kind of indirect light:

* ``cornell_far`` — a 5 m Cornell-style room (open front) seen from 13 m away through a 70 mm
  lens; a low sun shines in through the open front, a point light hangs under the ceiling.
* ``columned_hall`` — a closed 10 m × 6 m × 4.5 m hall with two rows of columns, lit only by a
  sun through a 2 m × 3 m roof opening: nearly all light on the walls is indirect.
* ``skinned_figure`` — a bent tube skinned to a 4-bone armature standing on a floor in front
  of a backdrop, under a sun and a large area light.
* ``thin_wall_rooms`` — a closed 6 m × 4 m room split by a 1.5 cm wall, one area light in the
  left half only; a camera above looks down through the clipped ceiling (as Cycles and
  ``raycast.camera_rays`` clip camera rays at the near plane, the ceiling still bounces light).

``SCENES`` maps the names to the builders; every builder returns the created objects by role.
Self-contained (only ``bpy``, ``mathutils`` and numpy) so tools can import it without pytest.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector

WIDTH, HEIGHT = 160, 120


# --------------------------------------------------------------------------- helpers

def _link(scene, obj):
    scene.collection.objects.link(obj)
    return obj


def _mesh(scene, name, vertices, faces, materials=(), face_materials=None, smooth=False):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(vertices, np.float64).reshape(-1, 3).tolist(), [],
                     [list(f) for f in faces])
    for material in materials:
        mesh.materials.append(material)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, np.int32))
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    return _link(scene, bpy.data.objects.new(name, mesh))


def _material(name, color):
    """A Principled BSDF at Blender's defaults with this linear RGB base colour."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    material.diffuse_color = (*color, 1.0)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    return material


def _box(lo, hi, inwards=False):
    """Vertices and quads of the axis-aligned box [lo, hi] (normals out, or in)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    vertices = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    if inwards:
        faces = [tuple(reversed(f)) for f in faces]
    return vertices, faces


def _block(scene, name, size, location, angle, material):
    """A box of ``size`` standing on ``location`` (its base centre), turned ``angle`` about Z."""
    sx, sy, sz = size
    vertices, faces = _box((-sx / 2, -sy / 2, 0.0), (sx / 2, sy / 2, sz))
    obj = _mesh(scene, name, vertices, faces, (material,))
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, angle)
    return obj


def _aim(obj, target):
    """Turn ``obj`` so its local −Z (cameras and lights look along it) points at ``target``."""
    direction = Vector(target) - Vector(obj.location)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def _light(scene, name, kind, location, target=None, direction=None, **settings):
    light = bpy.data.lights.new(name, kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = _link(scene, bpy.data.objects.new(name, light))
    obj.location = location
    if direction is not None:
        obj.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    elif target is not None:
        _aim(obj, target)
    return obj


def _camera(scene, name, location, target, lens, clip_start=0.1, clip_end=100.0):
    data = bpy.data.cameras.new(name)
    data.lens, data.clip_start, data.clip_end = lens, clip_start, clip_end
    camera = _link(scene, bpy.data.objects.new(name, data))
    camera.location = location
    _aim(camera, target)
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    return camera


def _black_world(scene):
    world = bpy.data.worlds.new("Black World")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.type == "BACKGROUND":
                node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
                node.inputs["Strength"].default_value = 0.0
    scene.world = world
    return world


def _finish(scene, objects):
    _black_world(scene)
    bpy.context.view_layer.update()
    return objects


# --------------------------------------------------------------------------- (a) far Cornell room

def build_cornell_far(scene):
    """A 5 m Cornell-style room, open towards −Y, seen from 13 m in front of its opening (70 mm lens).

    Interior x, y in [−2.5, 2.5], z in [0, 5]: white floor, ceiling and back wall, red left
    (x = −2.5) and green right wall, a short and a tall white block. A 1.5 W/m² sun (1° disc)
    shines in through the opening from the front-left, about 30° above the horizon; a 300 W
    point light (radius 10 cm) hangs at (0.5, 0.5, 4.3).
    """
    white = _material("Room White", (0.75, 0.75, 0.75))
    red = _material("Room Red", (0.7, 0.08, 0.06))
    green = _material("Room Green", (0.1, 0.6, 0.12))
    corners = [(x, y, z) for z in (0.0, 5.0) for y in (-2.5, 2.5) for x in (-2.5, 2.5)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]  # inwards
    room = _mesh(scene, "Room", corners, faces, (white, red, green), (0, 0, 0, 1, 2))
    short = _block(scene, "Short Block", (1.4, 1.4, 1.4), (0.9, -0.6, 0.0), 0.3, white)
    tall = _block(scene, "Tall Block", (1.4, 1.4, 2.9), (-0.95, 0.9, 0.0), -0.3, white)
    sun = _light(scene, "Sun", "SUN", (0.0, -8.0, 8.0), direction=(0.45, 0.75, -0.48),
                 energy=1.5, angle=math.radians(1.0))
    lamp = _light(scene, "Point", "POINT", (0.5, 0.5, 4.3), energy=300.0, shadow_soft_size=0.1)
    camera = _camera(scene, "Far Camera", (0.0, -13.0, 3.5), (0.0, 0.0, 2.3), lens=70.0,
                     clip_end=200.0)
    return _finish(scene, {"room": room, "short": short, "tall": tall, "sun": sun,
                           "light": lamp, "camera": camera})


# --------------------------------------------------------------------------- (b) columned hall

def build_columned_hall(scene):
    """A closed hall x in [−3, 3], y in [−5, 5], z in [0, 4.5] with a roof opening x in [−1, 1],
    y in [−1.5, 1.5]; two rows of four 0.5 m square columns (x = ±1.8) from floor to ceiling.
    Only light: a 20 W/m² sun (2° disc) through the opening, steep enough to reach the floor.
    The camera stands inside near the −Y end (eye height 1.7 m, 22 mm lens) looking down the hall.
    """
    floor_mat = _material("Hall Floor", (0.55, 0.45, 0.35))
    wall_mat = _material("Hall Walls", (0.7, 0.7, 0.65))
    column_mat = _material("Hall Columns", (0.6, 0.6, 0.6))
    x0, x1, y0, y1, z1 = -3.0, 3.0, -5.0, 5.0, 4.5
    hx, hy = 1.0, 1.5
    vertices, faces = _box((x0, y0, 0.0), (x1, y1, z1), inwards=True)
    walls = [f for i, f in enumerate(faces) if i not in (0, 1)]  # not floor (0), not ceiling (1)
    shell = _mesh(scene, "Hall Walls", vertices, walls, (wall_mat,))
    floor = _mesh(scene, "Hall Floor", [(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)],
                  [(0, 1, 2, 3)], (floor_mat,))
    # Ceiling with a hole: an 4 × 4 vertex grid on x ∈ {x0, −hx, hx, x1}, y ∈ {y0, −hy, hy, y1},
    # all cells but the centre one, facing down.
    xs, ys = (x0, -hx, hx, x1), (y0, -hy, hy, y1)
    grid = [(x, y, z1) for y in ys for x in xs]
    cells = [(i, j) for j in range(3) for i in range(3) if (i, j) != (1, 1)]
    ceiling = _mesh(scene, "Hall Ceiling", grid,
                    [(4 * j + i, 4 * (j + 1) + i, 4 * (j + 1) + i + 1, 4 * j + i + 1)
                     for i, j in cells], (wall_mat,))
    columns = [_block(scene, f"Column {k}", (0.5, 0.5, z1), (x, y, 0.0), 0.0, column_mat)
               for k, (x, y) in enumerate((x, y) for x in (-1.8, 1.8)
                                          for y in (-3.0, -1.0, 1.0, 3.0))]
    sun = _light(scene, "Sun", "SUN", (0.0, 0.0, 10.0), direction=(0.3, 0.35, -0.89),
                 energy=20.0, angle=math.radians(2.0))
    camera = _camera(scene, "Hall Camera", (0.3, -4.6, 1.7), (0.0, 2.0, 1.3), lens=22.0)
    return _finish(scene, {"walls": shell, "floor": floor, "ceiling": ceiling,
                           "columns": columns, "sun": sun, "camera": camera})


# --------------------------------------------------------------------------- (c) skinned figure

FIGURE_HEIGHT = 1.8
FIGURE_RADIUS = 0.2
FIGURE_BONES = 4
FIGURE_RINGS = 13
FIGURE_SEGMENTS = 20


def _tube(radius, height, rings, segments):
    angles = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    heights = np.linspace(0.0, height, rings)
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    vertices = np.concatenate([np.column_stack([ring, np.full(segments, h)]) for h in heights])
    faces = [(r * segments + s, r * segments + (s + 1) % segments,
              (r + 1) * segments + (s + 1) % segments, (r + 1) * segments + s)
             for r in range(rings - 1) for s in range(segments)]
    faces.append(tuple(reversed(range(segments))))
    top = (rings - 1) * segments
    faces.append(tuple(range(top, top + segments)))
    return vertices, faces, heights


def _ring_weights(heights, bones, length):
    """Tent-shaped weights (R, bones) along bones of equal length; rows sum to 1."""
    bone = length / bones
    centres = (np.arange(bones) + 0.5) * bone
    clamped = np.clip(heights, centres[0], centres[-1])
    w = np.maximum(0.0, 1.0 - np.abs(clamped[:, None] - centres[None]) / bone)
    return w / w.sum(axis=1, keepdims=True)


def _add_chain(scene, rig, names, step):
    """A connected chain of bones up local Z (edit mode through a context override)."""
    from voxgi.blender.scene_building import armature_edit_mode

    with armature_edit_mode(scene, rig) as bones:
        for i, name in enumerate(names):
            bone = bones.new(name)
            bone.head, bone.tail = (0.0, 0.0, i * step), (0.0, 0.0, (i + 1) * step)
            if i:
                bone.parent, bone.use_connect = bones[names[i - 1]], True


def build_skinned_figure(scene):
    """A 1.8 m tube (radius 0.2 m) skinned to 4 bones and bent sideways and forwards, standing on
    a 12 m floor in front of a 12 m × 4 m backdrop at y = 2, beside a 0.6 m cube. A 4 W/m² sun
    (0.5° disc) from the back-left, 50° high, and a 2 m square 400 W area light at the front-right.
    """
    floor_mat = _material("Floor Grey", (0.5, 0.5, 0.5))
    backdrop_mat = _material("Backdrop Blue", (0.35, 0.45, 0.7))
    figure_mat = _material("Figure Orange", (0.85, 0.4, 0.1))
    cube_mat = _material("Cube White", (0.8, 0.8, 0.8))
    floor = _mesh(scene, "Floor", [(-6, -6, 0), (6, -6, 0), (6, 2, 0), (-6, 2, 0)],
                  [(0, 1, 2, 3)], (floor_mat,))
    backdrop = _mesh(scene, "Backdrop", [(-6, 2, 0), (6, 2, 0), (6, 2, 4), (-6, 2, 4)],
                     [(0, 3, 2, 1)], (backdrop_mat,))
    cube = _block(scene, "Cube", (0.6, 0.6, 0.6), (1.0, 0.3, 0.0), 0.5, cube_mat)
    vertices, faces, heights = _tube(FIGURE_RADIUS, FIGURE_HEIGHT, FIGURE_RINGS, FIGURE_SEGMENTS)
    figure = _mesh(scene, "Figure", vertices, faces, (figure_mat,), smooth=True)
    rig = _link(scene, bpy.data.objects.new("Figure Rig", bpy.data.armatures.new("Figure Rig")))
    names = [f"Spine.{i}" for i in range(FIGURE_BONES)]
    _add_chain(scene, rig, names, FIGURE_HEIGHT / FIGURE_BONES)
    weights = _ring_weights(heights, FIGURE_BONES, FIGURE_HEIGHT)
    for b, name in enumerate(names):
        group = figure.vertex_groups.new(name=name)
        for r in np.nonzero(weights[:, b])[0]:
            ring = range(r * FIGURE_SEGMENTS, (r + 1) * FIGURE_SEGMENTS)
            group.add(list(ring), float(weights[r, b]), "REPLACE")
    modifier = figure.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    figure.parent = rig
    rig.location = (-0.4, 0.0, 0.0)
    # Bones run along their local Y (world Z here): rotating about the bone's X bends the chain
    # towards the camera, about its Z sideways.
    for name in names[1:]:
        pose = rig.pose.bones[name]
        pose.rotation_mode = "XYZ"
        pose.rotation_euler = (-0.15, 0.0, 0.3)
    sun = _light(scene, "Sun", "SUN", (0.0, 0.0, 10.0), direction=(0.45, -0.4, -0.8),
                 energy=4.0, angle=math.radians(0.5))
    area = _light(scene, "Area", "AREA", (3.5, -3.0, 3.0), target=(-0.2, 0.3, 0.6),
                  energy=400.0, size=2.0, shape="SQUARE")
    camera = _camera(scene, "Figure Camera", (0.3, -6.0, 1.8), (0.0, 0.5, 0.8), lens=40.0)
    return _finish(scene, {"floor": floor, "backdrop": backdrop, "cube": cube, "figure": figure,
                           "rig": rig, "sun": sun, "area": area, "camera": camera})


# --------------------------------------------------------------------------- (d) thin wall

THIN_WALL_HALF = 0.0075  # metres: the wall at x = 0 spans x in [−0.0075, 0.0075] (1.5 cm)


def build_thin_wall_rooms(scene):
    """A closed room x in [−3, 3], y in [−2, 2], z in [0, 2.8] (normals inwards) split by a
    closed 1.5 cm slab at x = 0 that reaches through floor, ceiling and side walls, so no ray
    passes between the halves: Cycles' right half (x > 0) is black. Only light: a 0.8 m square
    120 W area light under the ceiling of the left half, at (−1.6, 0.4, 2.75). Different
    colours per half (left floor beige, right floor grey-green, walls off-white).

    Camera: 30 mm lens at (0, 0, 6.5) looking straight down (image up = +Y), near plane 3.9 m,
    so camera rays start below the ceiling.
    """
    walls = _material("Rooms Walls", (0.75, 0.72, 0.68))
    left_floor = _material("Left Floor", (0.65, 0.55, 0.4))
    right_floor = _material("Right Floor", (0.4, 0.55, 0.45))
    divider = _material("Divider", (0.7, 0.7, 0.7))
    vertices, faces = _box((-3.0, -2.0, 0.0), (3.0, 2.0, 2.8), inwards=True)
    shell = _mesh(scene, "Rooms Shell", vertices, [f for i, f in enumerate(faces) if i != 0],
                  (walls,))
    floors = [_mesh(scene, name, [(a, -2, 0), (b, -2, 0), (b, 2, 0), (a, 2, 0)], [(0, 1, 2, 3)],
                    (mat,)) for name, a, b, mat in (("Left Floor", -3.0, 0.0, left_floor),
                                                    ("Right Floor", 0.0, 3.0, right_floor))]
    h = THIN_WALL_HALF
    vertices, faces = _box((-h, -2.001, -0.001), (h, 2.001, 2.801))
    wall = _mesh(scene, "Thin Wall", vertices, faces, (divider,))
    lamp = _light(scene, "Area", "AREA", (-1.6, 0.4, 2.75), direction=(0.0, 0.0, -1.0),
                  energy=120.0, size=0.8, shape="SQUARE")
    camera = _camera(scene, "Rooms Camera", (0.0, 0.0, 6.5), (0.0, 0.0, 0.0), lens=30.0,
                     clip_start=3.9)
    camera.rotation_euler = (0.0, 0.0, 0.0)  # straight down, image up = +Y
    return _finish(scene, {"shell": shell, "floors": floors, "wall": wall, "light": lamp,
                           "camera": camera})


def use_lambert_materials():
    """Replace every material's Principled BSDF by a Diffuse BSDF of its base colour (roughness
    0: Lambert). For checking units: with Principled's default dielectric layer Cycles'
    diffuse weight is the base colour × (1 − the layer's albedo), and the light bounced off a
    surface includes its glossy lobe; a Lambert surface reflects exactly base colour / π."""
    for material in bpy.data.materials:
        tree = material.node_tree
        if tree is None:
            continue
        for bsdf in [n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"]:
            diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
            diffuse.inputs["Color"].default_value = bsdf.inputs["Base Color"].default_value
            diffuse.inputs["Roughness"].default_value = 0.0
            for link in list(bsdf.outputs["BSDF"].links):
                tree.links.new(diffuse.outputs["BSDF"], link.to_socket)
            tree.nodes.remove(bsdf)


SCENES = {
    "cornell_far": build_cornell_far,
    "columned_hall": build_columned_hall,
    "skinned_figure": build_skinned_figure,
    "thin_wall_rooms": build_thin_wall_rooms,
}


def build(name, scene=None):
    """Build scene ``name`` of ``SCENES`` into ``scene`` (default: the context scene, which
    should be empty: ``bpy.ops.wm.read_factory_settings(use_empty=True)``)."""
    return SCENES[name](scene or bpy.context.scene)

"""A rigged character left as Blender's glTF/FBX importers leave Mixamo-style rigs (issue 22).

``build_character_room(scene, unit)`` builds a 1.8 m humanoid made of smooth tubes (torso,
head, two two-bone legs and arms; ~10k triangles with the default ``detail``) skinned to an
11-bone armature, posed, standing in a 6 m × 5 m × 3 m room (floor, three walls, ceiling;
the front is open towards the camera) lit by a sun through the open front and a ceiling area
light. ``unit`` is metres per model unit:

* ``unit=0.01`` — what the importers make of a centimetre rig: the armature object has scale
  0.01, the mesh vertices and the bones are in centimetres, and the mesh object is parented to
  the armature with an identity parent inverse (its world matrix carries the 0.01 too);
* ``unit=1`` — the same character with the scale applied (Object › Apply › Scale): metres
  everywhere, every object scale 1.

Both give the same world geometry and pose. Self-contained (``bpy``, ``mathutils``, numpy) so
tools/bench can import it without pytest.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector

WIDTH, HEIGHT = 160, 120

# (name, parent, head, tail) in metres; the chains the tubes are skinned to
BONES = (
    ("Hips", None, (0.0, 0.0, 0.90), (0.0, 0.0, 1.15)),
    ("Spine", "Hips", (0.0, 0.0, 1.15), (0.0, 0.0, 1.45)),
    ("Head", "Spine", (0.0, 0.0, 1.50), (0.0, 0.0, 1.80)),
    ("Thigh.L", "Hips", (0.11, 0.0, 0.90), (0.11, 0.0, 0.47)),
    ("Shin.L", "Thigh.L", (0.11, 0.0, 0.47), (0.11, 0.0, 0.04)),
    ("Thigh.R", "Hips", (-0.11, 0.0, 0.90), (-0.11, 0.0, 0.47)),
    ("Shin.R", "Thigh.R", (-0.11, 0.0, 0.47), (-0.11, 0.0, 0.04)),
    ("UpperArm.L", "Spine", (0.24, 0.0, 1.42), (0.30, 0.0, 1.12)),
    ("Forearm.L", "UpperArm.L", (0.30, 0.0, 1.12), (0.34, 0.0, 0.84)),
    ("UpperArm.R", "Spine", (-0.24, 0.0, 1.42), (-0.30, 0.0, 1.12)),
    ("Forearm.R", "UpperArm.R", (-0.30, 0.0, 1.12), (-0.34, 0.0, 0.84)),
)
# (bone chain, radius at the start, radius at the end, rings at detail 1)
TUBES = (
    (("Hips", "Spine"), 0.17, 0.19, 28),
    (("Head",), 0.10, 0.11, 16),
    (("Thigh.L", "Shin.L"), 0.08, 0.05, 30),
    (("Thigh.R", "Shin.R"), 0.08, 0.05, 30),
    (("UpperArm.L", "Forearm.L"), 0.05, 0.04, 24),
    (("UpperArm.R", "Forearm.R"), 0.05, 0.04, 24),
)
SEGMENTS = 32  # around every tube at detail 1
# pose: bone → XYZ Euler (radians) of its pose rotation
POSE = {
    "Spine": (0.12, 0.0, 0.15),
    "Head": (-0.1, 0.0, 0.35),
    "UpperArm.L": (0.6, 0.0, 0.5),
    "Forearm.L": (0.7, 0.0, 0.0),
    "UpperArm.R": (-0.3, 0.0, -0.2),
    "Thigh.L": (-0.35, 0.0, 0.0),
    "Shin.L": (0.6, 0.0, 0.0),
}


def _link(scene, obj):
    scene.collection.objects.link(obj)
    return obj


def _material(name, color):
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    material.diffuse_color = (*color, 1.0)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    return material


def _mesh(scene, name, vertices, faces, materials, smooth=False):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(vertices, np.float64).reshape(-1, 3).tolist(), [],
                     [list(f) for f in faces])
    for material in materials:
        mesh.materials.append(material)
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    return _link(scene, bpy.data.objects.new(name, mesh))


def _frame(axis):
    """Two unit vectors perpendicular to ``axis`` (and to each other)."""
    axis = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _tube(chain, r0, r1, rings, segments, bones):
    """A capped tube along the bone chain: vertices (V, 3) metres, quads, per-vertex weights
    {bone: (V,)} (tent weights along the chain, rows summing to 1)."""
    heads = [np.array(bones[name][1], float) for name in chain]
    tails = [np.array(bones[name][2], float) for name in chain]
    points = np.array([heads[0], *tails])
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    along = np.linspace(0.0, lengths.sum(), rings)
    starts = np.r_[0.0, np.cumsum(lengths)[:-1]]
    angles = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    vertices, weights = [], {name: [] for name in chain}
    centres = starts + lengths / 2
    for s in along:
        b = min(int(np.searchsorted(np.cumsum(lengths), s, side="right")), len(chain) - 1)
        t = (s - starts[b]) / lengths[b]
        centre = heads[b] + t * (tails[b] - heads[b])
        u, v = _frame(tails[b] - heads[b])
        radius = r0 + (r1 - r0) * s / lengths.sum()
        ring = centre + radius * (np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v)
        vertices.append(ring)
        if len(chain) == 1:
            w = np.ones(1)
        else:
            clamped = np.clip(s, centres[0], centres[-1])
            w = np.maximum(0.0, 1.0 - np.abs(clamped - centres) / (lengths.mean()))
            w /= w.sum()
        for name, value in zip(chain, w):
            weights[name].extend([value] * segments)
    faces = [(r * segments + k, r * segments + (k + 1) % segments,
              (r + 1) * segments + (k + 1) % segments, (r + 1) * segments + k)
             for r in range(rings - 1) for k in range(segments)]
    faces.append(tuple(reversed(range(segments))))
    top = (rings - 1) * segments
    faces.append(tuple(range(top, top + segments)))
    return np.concatenate(vertices), faces, {n: np.asarray(w) for n, w in weights.items()}


def character_geometry(detail: float = 1.0):
    """The character's rest mesh in metres: vertices (V, 3), faces, weights {bone: (V,)}."""
    bones = {name: (parent, head, tail) for name, parent, head, tail in BONES}
    segments = max(8, int(round(SEGMENTS * detail)))
    vertices, faces, weights, offset = [], [], {name: [] for name in bones}, 0
    for chain, r0, r1, rings in TUBES:
        v, f, w = _tube(chain, r0, r1, max(4, int(round(rings * detail))), segments, bones)
        vertices.append(v)
        faces.extend(tuple(i + offset for i in face) for face in f)
        for name in bones:
            weights[name].append(w.get(name, np.zeros(len(v))))
        offset += len(v)
    return (np.concatenate(vertices), faces,
            {name: np.concatenate(parts) for name, parts in weights.items()})


def _build_bones(scene, rig, unit):
    from voxgi.blender.scene_building import armature_edit_mode

    with armature_edit_mode(scene, rig) as edit:
        for name, parent, head, tail in BONES:
            bone = edit.new(name)
            bone.head = [c / unit for c in head]
            bone.tail = [c / unit for c in tail]
            if parent is not None:
                bone.parent = edit[parent]


def add_character(scene, unit: float = 0.01, detail: float = 1.0, location=(0.3, 0.4, 0.0),
                  turn: float = 0.4, name: str = "Character"):
    """The posed character as the importers leave it at ``unit`` metres per model unit (module
    doc). Returns (mesh object, armature object)."""
    vertices, faces, weights = character_geometry(detail)
    skin = _material(f"{name} Skin", (0.8, 0.45, 0.3))
    body = _mesh(scene, name, vertices / unit, faces, (skin,), smooth=True)
    rig = _link(scene, bpy.data.objects.new(f"{name} Rig", bpy.data.armatures.new(f"{name} Rig")))
    _build_bones(scene, rig, unit)
    for bone, w in weights.items():
        group = body.vertex_groups.new(name=bone)
        for value in np.unique(w[w > 0]):
            group.add(np.flatnonzero(w == value).tolist(), float(value), "REPLACE")
    modifier = body.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    body.parent = rig  # identity parent inverse: the mesh's world matrix carries the unit too
    rig.location = location
    rig.rotation_euler = (0.0, 0.0, turn)
    rig.scale = (unit, unit, unit)
    for bone, euler in POSE.items():
        pose = rig.pose.bones[bone]
        pose.rotation_mode = "XYZ"
        pose.rotation_euler = euler
    return body, rig


def _aim(obj, target):
    direction = Vector(target) - Vector(obj.location)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def build_character_room(scene, unit: float = 0.01, detail: float = 1.0):
    """The character (``add_character``) in a 6 × 5 × 3 m room open towards the camera (−Y).
    Returns the objects by role."""
    wall = _material("Wall", (0.7, 0.7, 0.65))
    floor_mat = _material("Floor", (0.45, 0.35, 0.25))
    red = _material("Red Wall", (0.7, 0.15, 0.1))
    x0, x1, y0, y1, top = -3.0, 3.0, -2.5, 2.5, 3.0
    room = {
        "floor": _mesh(scene, "Floor", [(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)],
                       [(0, 1, 2, 3)], (floor_mat,)),
        "ceiling": _mesh(scene, "Ceiling", [(x0, y0, top), (x0, y1, top), (x1, y1, top),
                                            (x1, y0, top)], [(0, 1, 2, 3)], (wall,)),
        "back": _mesh(scene, "Back Wall", [(x0, y1, 0), (x1, y1, 0), (x1, y1, top),
                                           (x0, y1, top)], [(0, 3, 2, 1)], (wall,)),
        "left": _mesh(scene, "Left Wall", [(x0, y0, 0), (x0, y1, 0), (x0, y1, top),
                                           (x0, y0, top)], [(0, 1, 2, 3)], (red,)),
        "right": _mesh(scene, "Right Wall", [(x1, y0, 0), (x1, y1, 0), (x1, y1, top),
                                             (x1, y0, top)], [(0, 3, 2, 1)], (wall,)),
    }
    body, rig = add_character(scene, unit, detail)
    sun_data = bpy.data.lights.new("Sun", "SUN")
    sun_data.energy, sun_data.angle = 3.0, math.radians(1.0)
    sun = _link(scene, bpy.data.objects.new("Sun", sun_data))
    sun.rotation_euler = Vector((0.3, 0.8, -0.5)).to_track_quat("-Z", "Y").to_euler()
    area_data = bpy.data.lights.new("Ceiling Light", "AREA")
    area_data.energy, area_data.size = 300.0, 1.5
    area = _link(scene, bpy.data.objects.new("Ceiling Light", area_data))
    area.location = (0.0, 0.0, 2.95)
    camera_data = bpy.data.cameras.new("Camera")
    camera_data.lens = 24.0
    camera = _link(scene, bpy.data.objects.new("Camera", camera_data))
    camera.location = (0.6, -4.2, 1.5)
    _aim(camera, (0.2, 0.5, 1.0))
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.type == "BACKGROUND":
                node.inputs["Strength"].default_value = 0.0
    scene.world = world
    bpy.context.view_layer.update()
    return {**room, "body": body, "rig": rig, "sun": sun, "area": area, "camera": camera}

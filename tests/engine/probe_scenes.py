"""Numpy versions of tests/blender/scenes.py's lighting scenes, for the probe tests."""
import numpy as np

from voxgi.voxgi_addon.scene.snapshot import LightData, MaterialData, MeshData, ObjectData, SceneSnapshot, WorldData


def _quads_to_tris(quads):
    return [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]


def box_mesh(name, lo, hi, inward=False, material=0, skip=()):
    """An axis-aligned box [lo, hi] as 12 triangles (normals outwards, or inwards); ``skip``
    names faces to leave out ('-x', '+x', '-y', '+y', '-z', '+z')."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = {"-z": (0, 2, 3, 1), "+z": (4, 5, 7, 6), "-y": (0, 1, 5, 4), "+y": (2, 6, 7, 3),
             "-x": (0, 4, 6, 2), "+x": (1, 3, 7, 5)}
    quads = [f for k, f in faces.items() if k not in skip]
    if inward:
        quads = [tuple(reversed(q)) for q in quads]
    tris = np.array(_quads_to_tris(quads), np.int32)
    mats = np.full(len(tris), material, np.int32) if np.ndim(material) == 0 else np.asarray(material, np.int32)
    return MeshData(name, np.array(v, np.float32), tris, mats)


def point_light(position, power, radius=0.05, color=(1.0, 1.0, 1.0)):
    m = np.eye(4)
    m[:3, 3] = position
    return LightData("Lamp", "POINT", np.array(color, np.float32), float(power), m, radius=radius)


def cornell_box(light_power=80.0):
    """tests/blender/scenes.py build_test_cornell_box without the blocks: x, y in [-1, 1],
    z in [0, 2], open at -y, red wall at x = -1, green at x = +1, point light at (0, 0, 1.5)."""
    mats = [MaterialData("white", np.array([0.8, 0.8, 0.8], np.float32)),
            MaterialData("red", np.array([0.8, 0.05, 0.05], np.float32)),
            MaterialData("green", np.array([0.05, 0.8, 0.05], np.float32))]
    # faces order in box_mesh without -y: -z, +z, +y, -x, +x (2 triangles each)
    material = np.repeat([0, 0, 0, 1, 2], 2)
    room = box_mesh("Room", (-1, -1, 0), (1, 1, 2), inward=True, material=material, skip=("-y",))
    obj = ObjectData("Room", "Room", np.eye(4))
    return SceneSnapshot({"Room": room}, mats, [obj], lights=[point_light((0, 0, 1.5), light_power)],
                         world=WorldData())


def thin_wall_room():
    """tests/blender/scenes.py build_thin_wall_room: a closed room x in [-2, 2], y in [-1, 1],
    z in [0, 2] split at x = 0 by a closed 2 cm slab; a 100 W point light at (-1, 0, 1.5)."""
    mats = [MaterialData("white", np.array([0.8, 0.8, 0.8], np.float32))]
    room = box_mesh("Room", (-2, -1, 0), (2, 1, 2), inward=True)
    wall = box_mesh("Wall", (-0.01, -1.001, -0.001), (0.01, 1.001, 2.001))
    objects = [ObjectData("Room", "Room", np.eye(4)), ObjectData("Wall", "Wall", np.eye(4))]
    return SceneSnapshot({"Room": room, "Wall": wall}, mats, objects,
                         lights=[point_light((-1, 0, 1.5), 100.0)], world=WorldData())

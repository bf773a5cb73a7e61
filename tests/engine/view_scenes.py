"""Synthetic rooms and cameras for the view-fit tests (numpy only)."""
import math

import numpy as np
from meshes import box
from snapshots import ObjectData, mesh, snapshot

from voxgi.voxgi_addon.scene.snapshot import CameraData


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """4x4 camera → world matrix of a camera at ``eye`` looking at ``target`` (local -Z)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(back, right), back, eye
    return m


def perspective(matrix, width=64, height=48, fov=math.radians(54.4), near=0.01, far=1000.0):
    """A Blender-style perspective camera (AUTO sensor fit; 54.4° ≈ a 35 mm lens)."""
    hx = math.tan(fov / 2)
    hy = hx * height / width
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = 1 / hx, 1 / hy
    p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1.0
    return CameraData("cam", matrix, p, (width, height), "PERSP", angle_x=fov, clip_start=near,
                      clip_end=far)


def open_room(size):
    """A Cornell-style room ``size`` metres wide: x, y in [-s/2, s/2], z in [0, s], open at
    -Y (normals inwards), with a short and a tall block inside. Returns (positions, triangles)."""
    h = size / 2
    corners = np.array([(x, y, z) for z in (0.0, size) for y in (-h, h) for x in (-h, h)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads]
    positions, triangles = [corners], [np.array(tris)]
    for sx, sz, cx, cy in ((0.3, 0.3, 0.17, -0.15), (0.3, 0.6, -0.2, 0.2)):
        p, t = box((sx * size, sx * size, sz * size), (cx * size, cy * size, sz * size / 2))
        triangles.append(t + sum(len(q) for q in positions))
        positions.append(p)
    return np.concatenate(positions), np.concatenate(triangles)


def room_scene(size, distance, width=64, height=48):
    """``open_room(size)`` seen through its open side by a camera ``distance`` room sizes from
    the room's centre (< 0.5: inside the room), aimed at the room's centre."""
    positions, triangles = open_room(size)
    centre = np.array([0.0, 0.0, size / 2])
    eye = centre + np.array([0.0, -distance * size, 0.1 * size])
    snap = snapshot([mesh("Room", positions, triangles)], [ObjectData("Room", "Room", np.eye(4))])
    return snap.__class__(**{**vars(snap), "camera": perspective(look_at(eye, centre), width,
                                                                 height)})

"""The scale scene of issue 18 point 3: a city block of box buildings, each crowned by a linked
duplicate of one detailed dome mesh (bpy data API, deterministic, background-safe).

``city_block(scene, side=24, rings=20, segments=40)``: ``side`` × ``side`` buildings on a 6 m
grid, each its own 12-triangle box mesh of a height between 4 and 16 m; on each an object
using the one shared dome mesh (a hemisphere of ``rings`` × ``segments``, 2·rings·segments −
segments triangles); a ground plane, a sun, a light grey-blue world and a camera looking over
the block from a corner. At the defaults: 576 buildings, 576 dome instances, 905k triangles.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector

SPACING = 6.0


def dome_mesh(name="Dome", rings=20, segments=40, radius=2.0):
    """A hemisphere (open at the bottom) on z = 0: (rings · segments) quads and a top fan."""
    theta = np.linspace(0.0, 0.5 * math.pi, rings + 1)[:-1]  # from the rim up, pole apart
    phi = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    rim = np.stack([np.outer(np.cos(theta), np.cos(phi)), np.outer(np.cos(theta), np.sin(phi)),
                    np.outer(np.sin(theta), np.ones_like(phi))], axis=-1).reshape(-1, 3)
    vertices = np.vstack([rim, [[0.0, 0.0, 1.0]]]) * radius
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            faces.append((a, b, b + segments, a + segments))
    pole = len(vertices) - 1
    top = (rings - 1) * segments
    faces += [(top + s, top + (s + 1) % segments, pole) for s in range(segments)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices.tolist(), [], faces)
    mesh.shade_smooth()
    return mesh


def _material(name, color):
    material = bpy.data.materials.new(name)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    material.diffuse_color = (*color, 1.0)
    return material


def _box_mesh(name, size):
    sx, sy, sz = size
    vertices = [(x, y, z) for z in (0.0, sz) for y in (-sy / 2, sy / 2) for x in (-sx / 2, sx / 2)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices, [], faces)
    return mesh


def city_block(scene, side: int = 24, rings: int = 20, segments: int = 40) -> int:
    """Build the block into ``scene``; returns its triangle count."""
    rng = np.random.default_rng(18)
    walls = _material("Walls", (0.7, 0.65, 0.6))
    copper = _material("Copper Dome", (0.3, 0.6, 0.5))
    ground = _material("Street", (0.3, 0.3, 0.3))
    dome = dome_mesh("Dome", rings, segments)
    dome.materials.append(copper)
    half = 0.5 * side * SPACING
    plane = bpy.data.meshes.new("Ground")
    plane.from_pydata([(-half - 10, -half - 10, 0), (half + 10, -half - 10, 0),
                       (half + 10, half + 10, 0), (-half - 10, half + 10, 0)], [], [(0, 1, 2, 3)])
    plane.materials.append(ground)
    scene.collection.objects.link(bpy.data.objects.new("Ground", plane))
    triangles = 2
    for i in range(side):
        for j in range(side):
            x, y = (i + 0.5) * SPACING - half, (j + 0.5) * SPACING - half
            height = float(rng.uniform(4.0, 16.0))
            box = _box_mesh(f"Building {i}-{j}", (4.4, 4.4, height))
            box.materials.append(walls)
            building = bpy.data.objects.new(f"Building {i}-{j}", box)
            building.location = (x, y, 0.0)
            scene.collection.objects.link(building)
            crown = bpy.data.objects.new(f"Dome {i}-{j}", dome)
            crown.location = (x, y, height)
            scene.collection.objects.link(crown)
            triangles += 12 + len(dome.polygons) * 2 - segments
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, math.radians(2.0)
    sun.rotation_euler = Vector((-0.4, 0.3, -0.85)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("Sky")
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.45, 0.55, 0.7, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.lens, camera.data.clip_end = 30.0, 1000.0
    camera.location = (-half - 12.0, -half - 12.0, 30.0)
    camera.rotation_euler = (Vector((0.0, 0.0, 4.0)) - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera
    bpy.context.view_layer.update()
    return triangles

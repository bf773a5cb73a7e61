"""The demo scene: a Cornell box with a tiled floor, a skinned tube and a rotating sphere.

Built from data API calls (``from_pydata``, ``bmesh``) so it works in background mode;
only the armature's bones need edit mode (``object.mode_set`` under a context override).
World space is Z-up, metres: the box interior spans x, y in [-1, 1], z in [0, 2], open
towards -Y where the camera stands.
"""
from __future__ import annotations

import math

import bmesh
import bpy
import numpy as np

from .scene_building import BoneSpec, add_bones, mesh_object, principled_material

DEMO_COLLECTION = "VoxGI Demo"
TUBE_HEIGHT = 1.2
TUBE_BONES = 3
TUBE_RINGS = 9
TUBE_SEGMENTS = 16


TILE_IMAGE = "VoxGI Tiles"
TILE_IMAGE_SIZE = 64
TILES = 4  # tiles across the image; the floor repeats it TILE_REPEAT times each way
TILE_REPEAT = 2


def tile_pixels(size: int = TILE_IMAGE_SIZE, tiles: int = TILES) -> np.ndarray:
    """(size, size, 4) float32 sRGB-encoded RGBA (row 0 at the bottom): light and dark stone
    tiles in a checker, each a little darker towards one corner, with grey grout lines."""
    y, x = np.mgrid[0:size, 0:size]
    cell = size // tiles
    odd = ((x // cell) + (y // cell)) % 2 == 1
    shade = 1.0 - 0.12 * ((x % cell) + (y % cell)) / (2 * cell)
    rgb = np.where(odd[..., None], (0.45, 0.42, 0.38), (0.85, 0.82, 0.76)) * shade[..., None]
    grout = ((x % cell) == 0) | ((y % cell) == 0)
    rgb[grout] = (0.3, 0.3, 0.3)
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=-1).astype(np.float32)


def tiled_material(name: str = "VoxGI Tiles"):
    """A Principled BSDF whose Base Color is a generated tile image, packed into the file,
    repeated TILE_REPEAT times through UV → Mapping → Image Texture."""
    image = bpy.data.images.new(TILE_IMAGE, TILE_IMAGE_SIZE, TILE_IMAGE_SIZE, alpha=False)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(tile_pixels().ravel())
    image.pack()
    material = principled_material(name, (0.6, 0.58, 0.53), roughness=0.6)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (TILE_REPEAT, TILE_REPEAT, 1.0)
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    links.new(coords.outputs["UV"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def _cornell_box(collection, white, red, green, tiles):
    corners = [(x, y, z) for z in (0.0, 2.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)]
    # Corner index = x + 2*y + 4*z (0/1 each); faces wind so normals point inwards.
    faces = [
        (0, 1, 3, 2),  # floor, +Z
        (4, 6, 7, 5),  # ceiling, -Z
        (2, 3, 7, 6),  # back wall, -Y
        (0, 2, 6, 4),  # left wall (red), +X
        (1, 5, 7, 3),  # right wall (green), -X
    ]
    box = mesh_object("Cornell Box", corners, faces, collection=collection,
                      materials=(white, red, green, tiles), face_materials=(3, 0, 0, 1, 2))
    layer = box.data.uv_layers.new(name="UVMap")
    # the floor's corners (0, 1, 3, 2) at (x, y) → UV ((x + 1) / 2, (y + 1) / 2)
    uv = np.empty(len(layer.data) * 2, np.float32)
    layer.data.foreach_get("uv", uv)
    uv[:8] = (0, 0, 1, 0, 1, 1, 0, 1)
    layer.data.foreach_set("uv", uv)
    return box


def _tube_geometry():
    """Vertices (R*S, 3) of a Z-up tube from z=0 to TUBE_HEIGHT, quad sides and n-gon caps."""
    radius = 0.15
    angles = np.linspace(0.0, 2 * math.pi, TUBE_SEGMENTS, endpoint=False)
    heights = np.linspace(0.0, TUBE_HEIGHT, TUBE_RINGS)
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    vertices = np.concatenate(
        [np.column_stack([ring, np.full(TUBE_SEGMENTS, h)]) for h in heights]
    )
    faces = []
    for r in range(TUBE_RINGS - 1):
        for s in range(TUBE_SEGMENTS):
            a, b = r * TUBE_SEGMENTS + s, r * TUBE_SEGMENTS + (s + 1) % TUBE_SEGMENTS
            faces.append((a, b, b + TUBE_SEGMENTS, a + TUBE_SEGMENTS))
    faces.append(tuple(reversed(range(TUBE_SEGMENTS))))
    top = (TUBE_RINGS - 1) * TUBE_SEGMENTS
    faces.append(tuple(range(top, top + TUBE_SEGMENTS)))
    return vertices, faces, heights


def tube_ring_weights(heights: np.ndarray, bone_count: int, length: float) -> np.ndarray:
    """Smooth (tent-shaped) bone weights for rings at ``heights`` along bones of equal length.

    heights : (R,) metres from the root; returns (R, bone_count) float, rows sum to 1.
    """
    bone_length = length / bone_count
    centres = (np.arange(bone_count) + 0.5) * bone_length
    clamped = np.clip(heights, centres[0], centres[-1])
    weights = np.maximum(0.0, 1.0 - np.abs(clamped[:, None] - centres[None, :]) / bone_length)
    return weights / weights.sum(axis=1, keepdims=True)


def _skinned_tube(scene, collection, material):
    location = (-0.45, 0.3, 0.0)
    vertices, faces, heights = _tube_geometry()
    tube = mesh_object("Skinned Tube", vertices, faces, collection=collection, materials=(material,))
    tube.data.shade_smooth()
    rig = bpy.data.objects.new("Tube Rig", bpy.data.armatures.new("Tube Rig"))
    collection.objects.link(rig)
    tube.location = rig.location = location
    names = [f"Tube.{i}" for i in range(TUBE_BONES)]
    step = TUBE_HEIGHT / TUBE_BONES
    add_bones(scene, rig, [
        BoneSpec(name, (0.0, 0.0, i * step), (0.0, 0.0, (i + 1) * step),
                 parent=names[i - 1] if i else None, connect=True)
        for i, name in enumerate(names)
    ])
    ring_weights = tube_ring_weights(heights, TUBE_BONES, TUBE_HEIGHT)
    for b, name in enumerate(names):
        group = tube.vertex_groups.new(name=name)
        for r in np.nonzero(ring_weights[:, b])[0]:
            ring = range(r * TUBE_SEGMENTS, (r + 1) * TUBE_SEGMENTS)
            group.add(list(ring), float(ring_weights[r, b]), "REPLACE")
    modifier = tube.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    tube.parent = rig
    tube.location = (0.0, 0.0, 0.0)
    for name in names[1:]:  # bend the upper bones a little, sideways as the camera sees it
        pose_bone = rig.pose.bones[name]
        pose_bone.rotation_mode = "XYZ"
        pose_bone.rotation_euler = (0.0, 0.0, 0.35)
    return tube, rig


def _rotating_sphere(collection, material, frames: int):
    mesh = bpy.data.meshes.new("Rotating Sphere")
    bm = bmesh.new()
    try:
        bm.loops.layers.uv.new("UVMap")
        bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=0.3, calc_uvs=True)
        bm.to_mesh(mesh)
    finally:
        bm.free()
    mesh.materials.append(material)
    mesh.shade_smooth()
    sphere = bpy.data.objects.new("Rotating Sphere", mesh)
    collection.objects.link(sphere)
    sphere.location = (0.45, -0.2, 0.3)
    sphere.rotation_euler = (0.0, 0.0, 0.0)
    sphere.keyframe_insert("rotation_euler", index=2, frame=1)
    sphere.rotation_euler = (0.0, 0.0, 2 * math.pi)
    sphere.keyframe_insert("rotation_euler", index=2, frame=frames)
    sphere.rotation_euler = (0.0, 0.0, 0.0)
    return sphere


def _camera(collection):
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    collection.objects.link(camera)
    camera.location = (0.0, -4.0, 1.0)
    camera.rotation_euler = (math.pi / 2, 0.0, 0.0)  # local -Z looks along +Y, into the box
    camera.data.lens = 35.0
    return camera


def _ceiling_light(collection):
    light = bpy.data.lights.new("Ceiling Light", "AREA")
    light.energy = 100.0  # watts
    light.size = 0.5
    obj = bpy.data.objects.new("Ceiling Light", light)
    collection.objects.link(obj)
    obj.location = (0.0, 0.0, 1.98)  # area lights shine along local -Z, i.e. down
    return obj


def _dim_world():
    world = bpy.data.worlds.new("VoxGI Demo World")
    world.color = (0.05, 0.05, 0.05)
    background = world.node_tree and next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if background is not None:
        background.inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
        background.inputs["Strength"].default_value = 1.0
    return world


def build_demo_scene(scene) -> dict[str, bpy.types.Object]:
    """Add the demo objects to ``scene`` in a new collection and make its camera active.

    Returns the created objects by role: 'box', 'light', 'tube', 'rig', 'sphere', 'camera'.
    The scene's frame range becomes 1..120 (one sphere turn); a world is created if
    the scene has none.
    """
    collection = bpy.data.collections.new(DEMO_COLLECTION)
    scene.collection.children.link(collection)
    white = principled_material("VoxGI White", (0.8, 0.8, 0.8))
    red = principled_material("VoxGI Red", (0.8, 0.05, 0.05))
    green = principled_material("VoxGI Green", (0.05, 0.8, 0.05))
    orange = principled_material("VoxGI Orange", (0.9, 0.4, 0.05), roughness=0.4)
    blue = principled_material("VoxGI Blue", (0.1, 0.2, 0.8), roughness=0.25, metallic=0.5)
    scene.frame_start, scene.frame_end = 1, 120
    tube, rig = _skinned_tube(scene, collection, orange)
    objects = {
        "box": _cornell_box(collection, white, red, green, tiled_material()),
        "light": _ceiling_light(collection),
        "tube": tube,
        "rig": rig,
        "sphere": _rotating_sphere(collection, blue, scene.frame_end),
        "camera": _camera(collection),
    }
    scene.camera = objects["camera"]
    if scene.world is None:
        scene.world = _dim_world()
    return objects

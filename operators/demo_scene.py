"""The demo scene: a Cornell box with a skinned tube and a rotating sphere.

Built from data API calls (``from_pydata``, ``bmesh``) so it works in background mode;
only the armature's bones need edit mode (``object.mode_set`` under a context override).
World space is Z-up, metres: the box interior spans x, y in [-1, 1], z in [0, 2], open
towards -Y where the camera stands.
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from typing import NamedTuple

import bmesh
import bpy
import numpy as np

DEMO_COLLECTION = "VoxGI Demo"
TUBE_HEIGHT = 1.2
TUBE_BONES = 3
TUBE_RINGS = 9
TUBE_SEGMENTS = 16


def principled_material(name: str, color, roughness: float = 0.5, metallic: float = 0.0):
    """A new material whose Principled BSDF has this linear RGB base colour."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5.0 creates materials without nodes
        material.use_nodes = True
    material.diffuse_color = (*color, 1.0)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    return material


def mesh_object(name: str, collection, vertices, faces, materials=(), face_materials=None):
    """A new mesh object from vertex (N, 3) and face index lists, linked into ``collection``.

    face_materials : optional (F,) int slot index per face.
    """
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(vertices, dtype=np.float64).tolist(), [], [list(f) for f in faces])
    for material in materials:
        mesh.materials.append(material)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _cornell_box(collection, white, red, green):
    corners = [(x, y, z) for z in (0.0, 2.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)]
    # Corner index = x + 2*y + 4*z (0/1 each); faces wind so normals point inwards.
    faces = [
        (0, 1, 3, 2),  # floor, +Z
        (4, 6, 7, 5),  # ceiling, -Z
        (2, 3, 7, 6),  # back wall, -Y
        (0, 2, 6, 4),  # left wall (red), +X
        (1, 5, 7, 3),  # right wall (green), -X
    ]
    box = mesh_object("Cornell Box", collection, corners, faces, (white, red, green), (0, 0, 0, 1, 2))
    box.data.uv_layers.new(name="UVMap")
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


class BoneSpec(NamedTuple):
    """A bone to create: head/tail in armature space (metres), parent by name, roll in radians."""

    name: str
    head: tuple[float, float, float]
    tail: tuple[float, float, float]
    parent: str | None = None
    deform: bool = True
    connect: bool = False
    roll: float = 0.0


@contextmanager
def armature_edit_mode(scene, armature_obj, view_layer=None):
    """Edit mode on ``armature_obj`` for the duration of the block; yields its edit bones.

    Bones only exist in edit mode: this enters it through a context override on
    ``view_layer`` (default: the scene's first; background-safe), returns to object mode
    and restores the active object. Raises RuntimeError when Blender refuses the mode
    (linked or hidden armature).
    """
    view_layer = view_layer or scene.view_layers[0]
    previous = view_layer.objects.active
    view_layer.objects.active = armature_obj
    try:
        with bpy.context.temp_override(
            scene=scene, view_layer=view_layer, active_object=armature_obj, object=armature_obj
        ):
            bpy.ops.object.mode_set(mode="EDIT")
            try:
                yield armature_obj.data.edit_bones
            finally:
                bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        view_layer.objects.active = previous


def add_bones(scene, armature_obj, bones) -> None:
    """Create ``bones`` (``BoneSpec``, parents before children) in ``armature_obj``."""
    with armature_edit_mode(scene, armature_obj) as edit_bones:
        for spec in bones:
            bone = edit_bones.new(spec.name)
            bone.head, bone.tail, bone.use_deform = spec.head, spec.tail, spec.deform
            bone.roll = spec.roll
            if spec.parent is not None:
                bone.parent, bone.use_connect = edit_bones[spec.parent], spec.connect


def _skinned_tube(scene, collection, material):
    location = (-0.45, 0.3, 0.0)
    vertices, faces, heights = _tube_geometry()
    tube = mesh_object("Skinned Tube", collection, vertices, faces, (material,))
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
        "box": _cornell_box(collection, white, red, green),
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


class VOXGI_OT_add_demo_scene(bpy.types.Operator):
    """Add a Cornell box with a skinned tube, a rotating sphere, a light and a camera"""

    bl_idname = "voxgi.add_demo_scene"
    bl_label = "Add VoxGI Demo Scene"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return False
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to add the demo scene")
            return False
        return True

    def execute(self, context):
        try:
            objects = build_demo_scene(context.scene)
        except RuntimeError as error:  # bpy raises RuntimeError when an edit is refused
            self.report({"ERROR"}, f"Could not build the demo scene: {error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Added the VoxGI demo scene ({len(objects)} objects)")
        return {"FINISHED"}


classes = (VOXGI_OT_add_demo_scene,)

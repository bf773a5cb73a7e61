"""A rigged character as Blender's glTF importer makes it (armature at 0.01), for the posed
updates (tests/blender/test_posed_update.py, tools/bench/bench_imported_blender.py).

``build_gltf_rig_room(scene)``: the ~11k-triangle character of ``unit_scale_scenes`` with a
textured skin (a packed 512² image through its UV map), in its 6 × 5 × 3 m room lit by the sun
and a point light, exported with Blender's own glTF exporter and imported back with default
settings: what users get from a Mixamo-style file (the armature object at scale 0.01, the mesh
vertices and bones in centimetres, the mesh parented to the armature). ``keyframe_walk`` gives
its rig a few bone rotations over frames, to play. Self-contained (``bpy``, numpy) so
tools/bench can import it without pytest.
"""
from __future__ import annotations

import math
import pathlib
import tempfile

import bpy
import numpy as np
import unit_scale_scenes

TEXTURE_SIZE = 512
DETAIL = 1.1  # ~11k triangles, as the character measured in docs/gi_pipeline.md


def _skin_texture(body) -> None:
    """A cylindrical UV map on the character and a packed noise image on its Base Color."""
    mesh = body.data
    layer = mesh.uv_layers.new(name="UVMap")
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    corner_vertex = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vertex)
    p = co.reshape(-1, 3)[corner_vertex]
    height = np.ptp(p[:, 2]) or 1.0
    uv = np.stack([(np.arctan2(p[:, 1], p[:, 0]) / (2 * math.pi)) % 1.0,
                   (p[:, 2] - p[:, 2].min()) / height], axis=1)
    layer.data.foreach_set("uv", uv.astype(np.float32).ravel())
    image = bpy.data.images.new("Skin Texture", TEXTURE_SIZE, TEXTURE_SIZE)
    rng = np.random.default_rng(7)
    pixels = np.empty((TEXTURE_SIZE, TEXTURE_SIZE, 4), np.float32)
    pixels[..., :3] = 0.35 + 0.5 * rng.random((TEXTURE_SIZE, TEXTURE_SIZE, 1)) * \
        np.array([0.9, 0.55, 0.4], np.float32)
    pixels[..., 3] = 1.0
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    tree = mesh.materials[0].node_tree
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])


def _clear(scene) -> None:
    for obj in list(scene.objects):
        bpy.data.objects.remove(obj)
    for collection in (bpy.data.meshes, bpy.data.materials, bpy.data.images, bpy.data.lights,
                       bpy.data.cameras, bpy.data.armatures, bpy.data.node_groups):
        for item in list(collection):
            collection.remove(item)


def build_gltf_rig_room(scene, detail: float = DETAIL) -> dict:
    """The imported rig in its room (module doc). Returns {"body", "rig", "sun", "lamp",
    "camera"} of the imported objects."""
    built = unit_scale_scenes.build_character_room(scene, 0.01, detail)
    _skin_texture(built["body"])
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    lamp.data.energy = 150.0
    lamp.location = (-1.2, -0.8, 2.4)
    scene.collection.objects.link(lamp)
    bpy.context.view_layer.update()
    with tempfile.TemporaryDirectory() as folder:
        glb = pathlib.Path(folder) / "rig.glb"
        assert bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB",
                                         export_cameras=True, export_lights=True) == {"FINISHED"}
        _clear(scene)
        assert bpy.ops.import_scene.gltf(filepath=str(glb)) == {"FINISHED"}
    for image in bpy.data.images:  # what the importer read from the GLB stays in the file
        if image.packed_file is None and image.source == "FILE":
            image.pack()
    objects = {o.name: o for o in scene.objects}
    rig = next(o for o in scene.objects if o.type == "ARMATURE")
    scene.camera = objects["Camera"]
    scene.render.resolution_x = unit_scale_scenes.WIDTH
    scene.render.resolution_y = unit_scale_scenes.HEIGHT
    world = bpy.data.worlds.new("Dim")
    world.color = (0.02, 0.02, 0.025)
    scene.world = world
    bpy.context.view_layer.update()
    return {"body": next(o for o in scene.objects if o.type == "MESH" and o.parent is rig),
            "rig": rig, "sun": objects["Sun"], "lamp": objects["Lamp"],
            "camera": objects["Camera"]}


def add_glowing_panel(scene, location=(-0.5, 2.45, 1.8), size=0.6, strength=8.0):
    """A square emissive panel (a Principled BSDF's Emission, warm white × ``strength``) of edge
    ``size`` standing against the room's back wall, facing into the room. Returns the object."""
    half = size / 2
    mesh = bpy.data.meshes.new("Glowing Panel")
    mesh.from_pydata([(-half, 0, -half), (half, 0, -half), (half, 0, half), (-half, 0, half)],
                     [], [(0, 3, 2, 1)])
    material = bpy.data.materials.new("Glow")
    if material.node_tree is None:  # Blender < 5.0 creates materials without nodes
        material.use_nodes = True
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Emission Color"].default_value = (1.0, 0.9, 0.7, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    mesh.materials.append(material)
    panel = bpy.data.objects.new("Glowing Panel", mesh)
    panel.location = location
    scene.collection.objects.link(panel)
    bpy.context.view_layer.update()
    return panel


def keyframe_walk(rig, frames: int = 10, start: int = 1) -> None:
    """Keyframes on a few of the rig's bones (arms and legs swinging) from ``start`` over
    ``frames`` frames: every frame poses the character anew."""
    swing = {"UpperArm.L": 0.5, "UpperArm.R": -0.5, "Thigh.L": -0.4, "Thigh.R": 0.4,
             "Forearm.L": 0.3}
    for name, amount in swing.items():
        bone = rig.pose.bones[name]
        bone.rotation_mode = "XYZ"
        for frame in range(start, start + frames):
            bone.rotation_euler = (amount * math.sin(0.7 * (frame - start)), 0.0, 0.0)
            bone.keyframe_insert("rotation_euler", frame=frame)

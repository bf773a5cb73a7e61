"""A textured metallic-roughness scene through Blender's own glTF exporter and importer (issue 22
point 3, acceptance (c)), for the tests against Cycles.

``gltf_room``: a floor whose Base Color is a checker image and whose roughness and metallic come
from a metallic-roughness image (glTF's G = roughness, B = metallic: polished metal bands
between rough stone cells), a plain red wall, a grey box with a rough-metal image of its own, a
fence card whose Base Color and Alpha come from one RGBA image, a sun and a point light (glTF's
punctual lights), a camera. The scene is built in code, exported as GLB with default settings,
every datablock removed (the exporter's defaults but for cameras and lights, which it leaves
out by default), and the GLB imported with default settings: what remains is what the
importer builds (Image Texture → Separate Color → Roughness / Metallic, the glTF Material
Output group, alpha from the image), with a black world. Deterministic, background-safe.
"""
from __future__ import annotations

import math
import pathlib
import tempfile

import bpy
import cutout_scenes
import gi_scenes
import numpy as np
import texture_scenes

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
MR_SIZE = 64


def metal_rough_pixels(size=MR_SIZE, bands=4, rough=(0.25, 0.8), metal_share=0.5):
    """(size, size, 4) float32 RGBA, row 0 at the bottom, a glTF metallic-roughness image
    (Non-Color): G = roughness, B = metallic; ``bands`` diagonal bands, ``metal_share`` of each
    polished metal (roughness rough[0], metallic 1), the rest rough dielectric (rough[1], 0)."""
    y, x = np.mgrid[0:size, 0:size] / float(size)
    metal = ((x + y) * bands) % 1.0 < metal_share
    out = np.zeros((size, size, 4), np.float32)
    out[..., 1] = np.where(metal, rough[0], rough[1])
    out[..., 2] = metal.astype(np.float32)
    out[..., 3] = 1.0
    return out


def metal_rough_image(name, **pattern):
    image = bpy.data.images.new(name, MR_SIZE, MR_SIZE, alpha=False, float_buffer=False)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(metal_rough_pixels(**pattern).ravel())
    image.pack()
    return image


def metal_rough_material(name, base_image, mr_image, color=(0.6, 0.6, 0.6)):
    """A Principled BSDF as glTF materials are authored: Base Color from ``base_image`` (or
    ``color``), Roughness and Metallic from the G and B channels of ``mr_image``."""
    material = gi_scenes._material(name, color)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    if base_image is not None:
        base = nodes.new("ShaderNodeTexImage")
        base.image = base_image
        links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
    mr = nodes.new("ShaderNodeTexImage")
    mr.image = mr_image
    split = nodes.new("ShaderNodeSeparateColor")
    links.new(mr.outputs["Color"], split.inputs["Color"])
    links.new(split.outputs["Green"], bsdf.inputs["Roughness"])
    links.new(split.outputs["Blue"], bsdf.inputs["Metallic"])
    return material


def _build_original(scene):
    red = gi_scenes._material("Red Wall", (0.7, 0.12, 0.08))
    floor = metal_rough_material("Floor", texture_scenes.checker_image(),
                                 metal_rough_image("Floor MR", bands=3, metal_share=0.3))
    box = metal_rough_material("Box", None, metal_rough_image("Box MR", bands=2, rough=(0.4, 0.9)),
                               color=(0.75, 0.7, 0.6))
    fence = cutout_scenes.cutout_material("Fence", cutout_scenes.fence_image())
    texture_scenes.quad(scene, "Floor", [(-3, -2.5, 0), (3, -2.5, 0), (3, 2.5, 0), (-3, 2.5, 0)],
                        floor, uv_scale=(2.0, 2.0))
    gi_scenes._mesh(scene, "Wall", [(-3, 2.5, 0), (3, 2.5, 0), (3, 2.5, 3), (-3, 2.5, 3)],
                    [(0, 1, 2, 3)], (red,))
    block = gi_scenes._block(scene, "Box", (1.0, 1.0, 0.9), (1.2, 0.8, 0.0), 0.4, box)
    layer = block.data.uv_layers.new(name="UVMap")
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    layer.data.foreach_set("uv", np.tile(corners, (len(block.data.polygons), 1)).ravel())
    texture_scenes.quad(scene, "Fence", [(-2.4, 0.0, 0), (-0.4, 0.4, 0), (-0.4, 0.4, 1.6),
                                         (-2.4, 0.0, 1.6)], fence)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.4, 0.75, -0.55), energy=2.5,
                     angle=math.radians(1.0))
    gi_scenes._light(scene, "Lamp", "POINT", (-0.5, -0.8, 2.6), energy=300.0)
    gi_scenes._camera(scene, "Camera", (0.3, -6.5, 1.8), (0.0, 0.4, 0.6), lens=28.0)
    bpy.context.view_layer.update()


def _clear_file(scene):
    for obj in list(scene.objects):
        bpy.data.objects.remove(obj)
    for collection in (bpy.data.meshes, bpy.data.materials, bpy.data.images, bpy.data.lights,
                       bpy.data.cameras, bpy.data.node_groups):
        for item in list(collection):
            collection.remove(item)


def build_gltf_room(scene):
    _build_original(scene)
    with tempfile.TemporaryDirectory() as folder:
        glb = pathlib.Path(folder) / "room.glb"
        assert bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB",
                                         export_cameras=True, export_lights=True) == {"FINISHED"}
        _clear_file(scene)
        assert bpy.ops.import_scene.gltf(filepath=str(glb)) == {"FINISHED"}
    for image in bpy.data.images:  # what the importer read from the GLB stays in the file
        if image.packed_file is None and image.source == "FILE":
            image.pack()
    scene.camera = next(o for o in scene.objects if o.type == "CAMERA")
    gi_scenes._finish(scene, {})


SCENES = {"gltf_room": build_gltf_room}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)

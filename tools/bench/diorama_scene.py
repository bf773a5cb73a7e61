"""A 100k+-triangle imported diorama for the viewport benchmarks (bpy data API, deterministic,
background-safe): every mesh its own (no instancing, so the BVH is built over all triangles, as
for a typical glTF download), built in code and round-tripped through Blender's own glTF
exporter and importer with default settings.

``diorama(scene, rocks=60, terrain=160)``: a noisy terrain of ``terrain`` × ``terrain`` quads with
a checker image texture, ``rocks`` unique noisy rocks (UV spheres of 24 × 32 faces, each its own
mesh) in three materials (one metallic), a sun, a point lamp, a sky colour and a camera over the
scene. At the defaults 142k triangles after the round trip. Returns the triangle count.
"""
from __future__ import annotations

import math
import pathlib
import tempfile

import bpy
import numpy as np
from mathutils import Vector


def _material(name, color, roughness=0.5, metallic=0.0, image=None):
    material = bpy.data.materials.new(name)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    if image is not None:
        node = material.node_tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        material.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def _checker(name="Diorama Checker", size=64, squares=8):
    ij = np.indices((size, size)) // (size // squares)
    tone = np.where((ij[0] + ij[1]) % 2 == 0, 0.55, 0.25)
    pixels = np.stack([tone * 0.9, tone, tone * 0.7, np.ones_like(tone)], axis=-1)
    image = bpy.data.images.new(name, size, size)
    image.pixels.foreach_set(pixels.astype(np.float32).ravel())
    image.pack()
    return image


def _terrain(scene, quads, material, rng):
    n = quads + 1
    x, y = np.meshgrid(np.linspace(-20, 20, n), np.linspace(-20, 20, n))
    z = (0.8 * np.sin(x * 0.35) * np.cos(y * 0.27) + 0.3 * np.sin(x * 1.3 + y * 0.9)
         + 0.05 * rng.standard_normal(x.shape))
    vertices = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(quads), np.arange(quads))
    a = (j * n + i).ravel()
    faces = np.stack([a, a + 1, a + n + 1, a + n], -1)
    mesh = bpy.data.meshes.new("Terrain")
    mesh.from_pydata(vertices.tolist(), [], faces.tolist())
    uv = mesh.uv_layers.new(name="UVMap")
    corner_uv = (vertices[faces.ravel(), :2] + 20.0) / 5.0
    uv.data.foreach_set("uv", corner_uv.astype(np.float32).ravel())
    mesh.materials.append(material)
    mesh.shade_smooth()
    scene.collection.objects.link(bpy.data.objects.new("Terrain", mesh))
    return 2 * quads * quads


def _rock(scene, name, centre, radius, material, rng, rings=24, segments=32):
    theta = np.linspace(0.0, math.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.outer(np.cos(theta), np.ones_like(phi))], -1).reshape(-1, 3)
    vertices = np.vstack([[[0, 0, 1]], ring, [[0, 0, -1]]])
    bumps = 1.0 + 0.18 * rng.standard_normal(len(vertices))
    vertices = vertices * (radius * bumps)[:, None] * np.array([1.0, 0.8, 0.6]) + centre
    faces = [(0, 1 + (s + 1) % segments, 1 + s) for s in range(segments)]
    for r in range(rings - 2):
        for s in range(segments):
            a, b = 1 + r * segments + s, 1 + r * segments + (s + 1) % segments
            faces.append((a, b, b + segments, a + segments))
    last = len(vertices) - 1
    base = 1 + (rings - 2) * segments
    faces += [(base + s, base + (s + 1) % segments, last) for s in range(segments)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices.tolist(), [], faces)
    mesh.materials.append(material)
    mesh.shade_smooth()
    scene.collection.objects.link(bpy.data.objects.new(name, mesh))
    return 2 * segments * (rings - 1)


def _build_original(scene, rocks: int, terrain: int) -> None:
    rng = np.random.default_rng(23)
    ground = _material("Ground", (0.6, 0.6, 0.6), 0.8, image=_checker())
    stones = (_material("Granite", (0.55, 0.5, 0.45), 0.6),
              _material("Moss Rock", (0.25, 0.4, 0.2), 0.9),
              _material("Ore", (0.8, 0.6, 0.35), 0.3, metallic=1.0))
    _terrain(scene, terrain, ground, rng)
    for k in range(rocks):
        x, y = rng.uniform(-15, 15, 2)
        _rock(scene, f"Rock {k}", (x, y, 0.6), float(rng.uniform(0.5, 1.6)), stones[k % 3], rng)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, math.radians(2.0)
    sun.rotation_euler = Vector((-0.4, 0.3, -0.85)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    lamp.data.energy, lamp.location = 800.0, (2.0, -3.0, 5.0)
    scene.collection.objects.link(lamp)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.lens, camera.data.clip_end = 28.0, 500.0
    camera.location = (-24.0, -24.0, 14.0)
    camera.rotation_euler = (Vector((0.0, 0.0, 0.0)) - camera.location).to_track_quat(
        "-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera


def _clear_file(scene) -> None:
    for obj in list(scene.objects):
        bpy.data.objects.remove(obj)
    for collection in (bpy.data.meshes, bpy.data.materials, bpy.data.images, bpy.data.lights,
                       bpy.data.cameras):
        for item in list(collection):
            collection.remove(item)


def diorama(scene, rocks: int = 60, terrain: int = 160) -> int:
    """Build the diorama into ``scene`` through a glTF round trip (module doc); returns its
    triangle count."""
    _build_original(scene, rocks, terrain)
    with tempfile.TemporaryDirectory() as folder:
        glb = pathlib.Path(folder) / "diorama.glb"
        assert bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB",
                                         export_cameras=True, export_lights=True) == {"FINISHED"}
        _clear_file(scene)
        assert bpy.ops.import_scene.gltf(filepath=str(glb)) == {"FINISHED"}
    for image in bpy.data.images:  # what the importer read from the GLB stays in the file
        if image.packed_file is None and image.source == "FILE":
            image.pack()
    scene.camera = next(o for o in scene.objects if o.type == "CAMERA")
    world = bpy.data.worlds.new("Sky")
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.45, 0.55, 0.7, 1.0)
    scene.world = world
    scene.render.engine = "VOXGI"
    bpy.context.view_layer.update()
    return sum(len(p.vertices) - 2 for o in scene.objects if o.type == "MESH"
               for p in o.data.polygons)

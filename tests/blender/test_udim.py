"""UDIM images (tiled textures, as character artists paint them): each UV square reads its own
tile, as Cycles draws it, from tile files or packed tiles. They all read tile 1001 (a bake over
UV [0, 1]²)."""
from __future__ import annotations

import math
import os

import bpy
import numpy as np
from cycles_reference import render_cycles_passes

WIDTH, HEIGHT = 96, 36
# tile → its colour (a darker lower-left quarter shows its orientation)
TILES = {1001: (0.8, 0.1, 0.1), 1002: (0.1, 0.1, 0.8), 1011: (0.1, 0.7, 0.1)}
# the strip's quads, left to right, and the UV square each covers
QUADS = (1001, 1002, 1011)


def linear(colour):
    """The linear colour Cycles reads of a byte tile painted with (sRGB) ``colour``."""
    from voxgi.voxgi_addon.scene.textures import srgb_to_linear

    return srgb_to_linear(np.asarray(colour, np.float32))


def tile_pixels(colour, size=16):
    pixels = np.ones((size, size, 4), np.float32)
    pixels[..., :3] = colour
    pixels[: size // 2, : size // 2, :3] *= 0.5
    return pixels


def write_tiles(folder, tiles=TILES, size=16):
    for number, colour in tiles.items():
        image = bpy.data.images.new(f"tile {number}", size, size)
        image.pixels.foreach_set(tile_pixels(colour, size).ravel())
        image.filepath_raw = os.path.join(folder, f"paint.{number}.png")
        image.file_format = "PNG"
        image.save()
        bpy.data.images.remove(image)


def strip_scene(folder):
    """Three unit quads side by side facing the camera, each over one tile's UV square, with a
    Principled BSDF whose Base Color is the UDIM image."""
    scene = bpy.context.scene
    write_tiles(folder)
    vertices, faces, uvs = [], [], []
    for i, number in enumerate(QUADS):
        u, v = (number - 1001) % 10, (number - 1001) // 10
        x, base = -1.5 + i, len(vertices)
        vertices += [(x, 0, -0.5), (x + 1, 0, -0.5), (x + 1, 0, 0.5), (x, 0, 0.5)]
        faces.append((base, base + 1, base + 2, base + 3))
        uvs += [(u, v), (u + 1, v), (u + 1, v + 1), (u, v + 1)]
    mesh = bpy.data.meshes.new("Strip")
    mesh.from_pydata(vertices, [], faces)
    layer = mesh.uv_layers.new(name="UVMap")
    for loop, uv in zip(layer.data, uvs):
        loop.uv = uv
    scene.collection.objects.link(bpy.data.objects.new("Strip", mesh))
    image = bpy.data.images.load(os.path.join(folder, "paint.1001.png"))
    image.source = "TILED"
    image.filepath = os.path.join(folder, "paint.<UDIM>.png")
    material = bpy.data.materials.new("Painted")
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    mesh.materials.append(material)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location, camera.rotation_euler = (0, -5.0, 0), (math.pi / 2, 0, 0)  # 3.6 m wide
    scene.camera = camera
    world = bpy.data.worlds.new("World")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    scene.world = world
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    return scene, image


def quad_colours(diffuse_color):
    """The mean Diffuse Color of each quad's upper-right quarter (its tile's plain colour),
    texels and pixels away from its edges."""
    per_metre = WIDTH / 3.6
    rows = slice(int(HEIGHT / 2 - 0.4 * per_metre), int(HEIGHT / 2 - 0.15 * per_metre))
    out = []
    for i in range(len(QUADS)):
        left = WIDTH / 2 + (i - 1.5) * per_metre
        columns = slice(int(left + 0.65 * per_metre), int(left + 0.9 * per_metre))
        out.append(diffuse_color[rows, columns].reshape(-1, 3).mean(axis=0))
    return np.array(out)


def preview(path):
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    assert bpy.ops.voxgi.render_preview(filepath=str(path)) == {"FINISHED"}
    return read_exr_passes(str(path))


def test_each_uv_square_reads_its_own_tile_as_in_cycles(voxgi, tmp_path):
    scene, _ = strip_scene(str(tmp_path))
    cycles = quad_colours(render_cycles_passes(scene, WIDTH, HEIGHT, samples=16)["Diffuse Color"])
    ours = quad_colours(preview(tmp_path / "p.exr")["Diffuse Color"])
    expected = linear([TILES[n] for n in QUADS])
    np.testing.assert_allclose(cycles, expected, atol=0.03)  # the scene is what it says
    np.testing.assert_allclose(ours, cycles, atol=0.03)


def test_packed_tiles_and_a_repainted_tile_file(voxgi, tmp_path):
    """Packed tiles are read from the file's bytes (the tile files deleted); an unpacked tile
    file painted again on disk is read again."""
    scene, image = strip_scene(str(tmp_path))
    image.pack()
    for number in TILES:
        os.remove(tmp_path / f"paint.{number}.png")
    ours = quad_colours(preview(tmp_path / "packed.exr")["Diffuse Color"])
    np.testing.assert_allclose(ours, linear([TILES[n] for n in QUADS]), atol=0.03)

    image.unpack(method="WRITE_ORIGINAL")  # the tiles are files again
    image.filepath = str(tmp_path / "paint.<UDIM>.png")
    write_tiles(str(tmp_path), {1002: (0.8, 0.8, 0.1)})
    os.utime(tmp_path / "paint.1002.png", (1e9, 2e9))
    image.reload()
    ours = quad_colours(preview(tmp_path / "repainted.exr")["Diffuse Color"])
    np.testing.assert_allclose(ours[1], linear((0.8, 0.8, 0.1)), atol=0.03)


def test_the_atlas_lays_tiles_as_the_uv_plane_and_stays_within_the_size_limit(voxgi, tmp_path, monkeypatch):
    from voxgi.blender.snapshot import udim
    from voxgi.blender.snapshot.materials import image_rgb

    _, image = strip_scene(str(tmp_path))
    assert udim.layout(image) == (2, 2)
    monkeypatch.setattr(udim, "MAX_SIZE", 16)  # 16-texel tiles, 2 × 2 cells: halved to 8
    atlas = image_rgb(image)
    assert atlas.shape == (16, 16, 3)
    for number, colour in TILES.items():
        column, row = udim.cell(number)
        np.testing.assert_allclose(atlas[row * 8 + 6, column * 8 + 6], linear(colour), atol=0.01)
    np.testing.assert_allclose(atlas[12, 12], udim.MISSING[:3])  # 1012: no tile
    np.testing.assert_allclose(udim.mean_over_tiles(atlas, image),
                               np.mean([np.mean(linear(tile_pixels(c)[..., :3]).reshape(-1, 3), axis=0)
                                        for c in TILES.values()], axis=0), atol=0.01)


def test_a_tile_whose_file_is_gone_is_drawn_magenta_as_cycles_draws_it_and_named(voxgi, tmp_path):
    from voxgi.blender.snapshot import udim
    from voxgi.blender.snapshot.scene import take_snapshot

    scene, _ = strip_scene(str(tmp_path))
    os.remove(tmp_path / "paint.1002.png")
    warnings = take_snapshot(scene, bpy.context.evaluated_depsgraph_get()).warnings
    named = [w for w in warnings if "UDIM tile 1002" in w]
    assert len(named) == 1 and "'Painted'" in named[0] and "magenta" in named[0], warnings
    cycles = quad_colours(render_cycles_passes(scene, WIDTH, HEIGHT, samples=16)["Diffuse Color"])
    ours = quad_colours(preview(tmp_path / "p.exr")["Diffuse Color"])
    # Cycles' magenta (its Diffuse Color: the colour under the Principled coat's ~4% Fresnel)
    assert cycles[1][0] > 0.9 and cycles[1][2] > 0.9 and cycles[1][1] < 0.03, cycles[1]
    np.testing.assert_allclose(ours, cycles, atol=0.03)
    assert udim.missing_tiles(bpy.data.images["paint.1001.png"]) == [1002]

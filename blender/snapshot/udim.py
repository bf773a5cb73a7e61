"""UDIM images (``Image.source`` 'TILED'): their tiles side by side in one atlas texture.

A UDIM image is one image node over many UV squares: tile 1001 + u + 10 v (u in 0–9) covers
UV [u, u + 1] × [v, v + 1], each tile its own file (``tex.1001.png`` …, the path's ``<UDIM>``
or ``<UVTILE>`` token) or packed. Blender's ``Image.pixels`` holds tile 1001 alone, and a bake
covers UV [0, 1]², so every tile was drawn with tile 1001's texels. Here the tiles are read one
by one and laid out as the UV plane lays them out: cell (column u, row v) of a ``layout`` of
``columns`` × ``rows`` cells, so that the texture's UV transform is a scale (1 / columns,
1 / rows). A cell without a tile holds Cycles' missing-image magenta, as Cycles draws UVs
there. The atlas is kept within the textures' ``MAX_SIZE`` (each tile halved alike).
"""
from __future__ import annotations

import hashlib
import os
import tempfile

import bpy
import numpy as np

from ...voxgi_addon.scene.textures import MAX_SIZE, within_max_size

MISSING = (1.0, 0.0, 1.0, 1.0)  # Cycles' colour of a UV square the image has no tile for


def cell(number: int) -> tuple[int, int]:
    """(column, row) of UDIM tile ``number`` (1001 → (0, 0), 1012 → (1, 1))."""
    row, column = divmod(number - 1001, 10)
    return column, row


def layout(image) -> tuple[int, int]:
    """(columns, rows) of the UV cells the atlas of ``image`` covers: from UV (0, 0) to its
    furthest tile."""
    cells = [cell(tile.number) for tile in image.tiles]
    return max(c for c, _ in cells) + 1, max(r for _, r in cells) + 1


def uv_scale(image) -> np.ndarray:
    """(2, 2) scale taking UVs to the atlas' [0, 1]²."""
    columns, rows = layout(image)
    return np.diag([1.0 / columns, 1.0 / rows])


def tile_path(image, number: int) -> str:
    """The file of tile ``number``: the image's path with its ``<UDIM>`` (1001) or
    ``<UVTILE>`` (u1_v1) token replaced."""
    path = bpy.path.abspath(image.filepath, library=image.library)
    column, row = cell(number)
    return path.replace("<UDIM>", str(number)).replace("<UVTILE>", f"u{column + 1}_v{row + 1}")


def content_key(image) -> tuple:
    """What identifies the tiles' content: each tile's number and file modification time, or
    a hash of its packed bytes."""
    packed = {p.tile_number: p for p in image.packed_files}
    key = []
    for tile in image.tiles:
        if tile.number in packed:
            data = packed[tile.number].packed_file
            key.append((tile.number, hashlib.blake2b(bytes(data.data), digest_size=16).hexdigest()))
            continue
        path = tile_path(image, tile.number)
        key.append((tile.number, path, os.path.getmtime(path) if os.path.exists(path) else None,
                    tuple(tile.generated_color) if tile.is_generated_tile else None))
    return tuple(key)


def missing_tiles(image) -> list[int]:
    """The numbers of the image's tiles that have no pixels to read: neither packed nor filled
    in Blender, and no file at their path (``atlas`` leaves their cells magenta, as Cycles
    draws them)."""
    packed = {p.tile_number for p in image.packed_files}
    return [tile.number for tile in image.tiles
            if tile.number not in packed and not tile.is_generated_tile
            and not os.path.exists(tile_path(image, tile.number))]


def mean_over_tiles(pixels: np.ndarray, image) -> np.ndarray:
    """The mean of an atlas' channels over the cells of tiles (not the missing ones)."""
    columns, rows = layout(image)
    h, w = pixels.shape[0] // rows, pixels.shape[1] // columns
    cells = [pixels[r * h:(r + 1) * h, c * w:(c + 1) * w] for c, r in map(cell, (t.number for t in image.tiles))]
    return np.mean([c.reshape(-1, c.shape[-1]).mean(axis=0, dtype=np.float64) for c in cells], axis=0)


def atlas(image, read) -> np.ndarray | None:
    """(H, W, C) float32 atlas of ``image``'s tiles (row 0 = bottom, as ``Image.pixels``), each
    read by ``read(tile image)`` — the C-channel pixels of a temporary ``bpy.types.Image`` of
    one tile file, in ``image``'s colour space — or None when no tile has pixels. Raises what
    ``read`` raises."""
    columns, rows = layout(image)
    tiles = {}
    for tile in image.tiles:
        pixels = _tile_pixels(image, tile, read)
        if pixels is not None:
            tiles[tile.number] = pixels
    if not tiles:
        return None
    height = max(p.shape[0] for p in tiles.values())
    width = max(p.shape[1] for p in tiles.values())
    while (columns * width > MAX_SIZE or rows * height > MAX_SIZE) and max(width, height) > 1:
        width, height = max(1, (width + 1) // 2), max(1, (height + 1) // 2)
    channels = next(iter(tiles.values())).shape[2]
    out = np.empty((rows * height, columns * width, channels), np.float32)
    out[...] = np.asarray(MISSING, np.float32)[:channels] if channels > 1 else MISSING[3]
    for number, pixels in tiles.items():
        column, row = cell(number)
        out[row * height:(row + 1) * height, column * width:(column + 1) * width] = \
            _resized(pixels, width, height)
    return out


def _resized(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """``pixels`` halved towards (height, width) as mip levels are, then nearest texels."""
    pixels = within_max_size(pixels, max(width, height))
    if pixels.shape[:2] == (height, width):
        return pixels
    rows = np.minimum((np.arange(height) + 0.5) * pixels.shape[0] // height, pixels.shape[0] - 1)
    columns = np.minimum((np.arange(width) + 0.5) * pixels.shape[1] // width, pixels.shape[1] - 1)
    return pixels[rows.astype(np.int64)][:, columns.astype(np.int64)]


def _tile_pixels(image, tile, read) -> np.ndarray | None:
    """``read`` of a temporary image holding one tile: its file, its packed bytes, or for a
    tile filled in Blender (Image › New, Tiled) a generated image of its size and colour."""
    folder = loaded = None
    try:
        packed = next((p for p in image.packed_files if p.tile_number == tile.number), None)
        if tile.is_generated_tile and packed is None:
            width, height = tile.generated_width, tile.generated_height
            loaded = bpy.data.images.new("VoxGI UDIM tile", width, height, alpha=True,
                                         float_buffer=tile.use_generated_float)
            loaded.generated_color = tile.generated_color
        else:
            if packed is not None:
                folder = tempfile.mkdtemp(prefix="voxgi-udim-")
                path = os.path.join(folder, "tile" + (os.path.splitext(packed.filepath)[1] or ".png"))
                with open(path, "wb") as file:
                    file.write(bytes(packed.packed_file.data))
            else:
                path = tile_path(image, tile.number)
                if not os.path.exists(path):
                    return None
            loaded = bpy.data.images.load(path, check_existing=False)
        loaded.colorspace_settings.name = image.colorspace_settings.name
        loaded.alpha_mode = image.alpha_mode
        return read(loaded)
    finally:
        if loaded is not None:
            bpy.data.images.remove(loaded)
        if folder is not None:
            for name in os.listdir(folder):
                os.remove(os.path.join(folder, name))
            os.rmdir(folder)

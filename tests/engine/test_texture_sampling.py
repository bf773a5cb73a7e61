"""Materials per texel (voxgi_addon/scene/textures.py): sampling as Cycles' image node
(interpolation, extension, Mapping), mip pyramids, the atlas the GPU samples, surface points
of a snapshot's triangles, and the voxelizer's per-texel albedo."""
import numpy as np
import pytest

from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import (
    MaterialData,
    MeshData,
    ObjectData,
    SceneSnapshot,
    TextureData,
)
from voxgi.voxgi_addon.scene.textures import (
    HALF,
    linear_to_srgb,
    mip_pyramid,
    pack_atlas,
    sample_level,
    sample_texture,
    srgb_to_linear,
)
from voxgi.voxgi_addon.voxelize.attributes import average_attributes
from voxgi.voxgi_addon.voxelize.scene_caches import texel_albedo
from voxgi.voxgi_addon.voxelize.surface import voxelize_triangles


def ramp(width=8, height=4):
    """Pixels whose red is the texel's column, green its row (row 0 at the bottom)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    return np.stack([x, y, np.zeros_like(x)], axis=-1)


def checker(size=16, cells=4, dark=0.1, light=0.9):
    y, x = np.mgrid[0:size, 0:size]
    odd = ((x // (size // cells)) + (y // (size // cells))) % 2 == 1
    return np.repeat(np.where(odd, dark, light)[..., None], 3, axis=-1).astype(np.float32)


def test_bilinear_between_texel_centres():
    image = ramp()
    # the centre of texel (3, 2) and halfway to (4, 2) and (3, 3)
    s = np.float32([(3.5) / 8, 4.0 / 8, 3.5 / 8])
    t = np.float32([2.5 / 4, 2.5 / 4, 3.0 / 4])
    out = sample_level(image, s, t, "Linear", "EXTEND")
    np.testing.assert_allclose(out[:, :2], [[3.0, 2.0], [3.5, 2.0], [3.0, 2.5]], atol=1e-5)


def test_extensions_and_closest():
    image = ramp()
    s = np.float32([-0.5 / 8, 8.5 / 8, 1.2])
    t = np.float32([0.5 / 4, 0.5 / 4, 0.5 / 4])
    repeat = sample_level(image, s, t, "Closest", "REPEAT")
    np.testing.assert_allclose(repeat[:, 0], [7.0, 0.0, 1.0])  # 1.2 wraps to 0.2 → column 1
    extend = sample_level(image, s, t, "Closest", "EXTEND")
    np.testing.assert_allclose(extend[:, 0], [0.0, 7.0, 7.0])
    clip = sample_level(image, s, t, "Closest", "CLIP")
    np.testing.assert_allclose(clip[:, 0], [0.0, 0.0, 0.0])
    # Linear at the border with Repeat blends the last and first columns
    edge = sample_level(image, np.float32([0.0]), np.float32([0.5 / 4]), "Linear", "REPEAT")
    assert edge[0, 0] == pytest.approx(3.5)


def test_mapping_scales_the_uv():
    texture = TextureData("r", ramp(), "Closest", "REPEAT", np.array([[2.0, 0, 0.25], [0, 1, 0]]))
    out = sample_texture(texture, np.float32([[0.1, 0.4]]))
    # s = 2·0.1 + 0.25 = 0.45 → column 3; t = 0.4 → row 1
    np.testing.assert_allclose(out[0, :2], [3.0, 1.0])


def test_mip_levels_keep_the_mean_and_lod_blends():
    image = checker(16, 4)
    levels = mip_pyramid(image)
    assert [level.shape[:2] for level in levels] == [(16, 16), (8, 8), (4, 4), (2, 2), (1, 1)]
    for level in levels:
        assert level.mean() == pytest.approx(image.mean(), abs=2e-3)
    # stored at half precision, as the GPU atlas holds them
    assert np.array_equal(levels[0], levels[0].astype(HALF).astype(np.float32))
    texture = TextureData("c", image, key="checker")
    uv = np.float32([[0.1, 0.1]] * 3)
    out = sample_texture(texture, uv, np.float32([0.0, 4.0, 2.5]))
    assert out[0, 0] == pytest.approx(levels[0][1, 1, 0], abs=1e-3)  # a texel of a cell
    assert out[1, 0] == pytest.approx(image.mean(), abs=2e-3)      # the 1 × 1 level
    half = 0.5 * (sample_texture(texture, uv[:1], np.float32([2.0])) +
                  sample_texture(texture, uv[:1], np.float32([3.0])))
    np.testing.assert_allclose(out[2], half[0], atol=1e-5)


def test_odd_sizes_pad_with_their_edge():
    image = ramp(5, 3)
    levels = mip_pyramid(image)
    assert [level.shape[:2] for level in levels] == [(3, 5), (2, 3), (1, 2), (1, 1)]
    # the last column of level 1 averages column 4 with itself
    assert levels[1][0, 2, 0] == pytest.approx(4.0, abs=1e-2)


def test_atlas_holds_every_level_where_the_table_says():
    textures = (TextureData("a", checker(16, 4), key="a"), TextureData("b", ramp(8, 4), key="b",
                                                                       interpolation="Closest",
                                                                       extension="CLIP"))
    atlas, table = pack_atlas(textures)
    for i, texture in enumerate(textures):
        levels = mip_pyramid(texture.pixels)
        assert table[i, 0, 3] == len(levels)
        for k, level in enumerate(levels):
            x0, y0, w, h = table[i, 3 + k].astype(int)
            assert (w, h) == (level.shape[1], level.shape[0])
            np.testing.assert_array_equal(atlas[y0:y0 + h, x0:x0 + w, :3], level)
    assert table[1, 1, 3] == 1 and table[1, 2, 0] == 2  # Closest, Clip
    # no two levels overlap: the atlas holds exactly the levels' texels
    total = sum(level.size // 3 for t in textures for level in mip_pyramid(t.pixels))
    used = np.zeros(atlas.shape[:2], int)
    for i, texture in enumerate(textures):
        for k in range(int(table[i, 0, 3])):
            x0, y0, w, h = table[i, 3 + k].astype(int)
            used[y0:y0 + h, x0:x0 + w] += 1
    assert used.max() == 1 and used.sum() == total


def test_a_byte_srgb_image_blends_its_texels_in_srgb():
    """Cycles blends a byte sRGB image's encoded texels and decodes the blend (measured with
    Cycles: half-way between a black and a white texel it reads 0.23, not 0.5; a float image
    reads 0.5): a flagged texture does the same, Closest reads its texels either way."""
    two = np.float32([[[0, 0, 0], [1, 1, 1]]])  # one row: black, white (linear)
    s = np.float32([0.25, 0.375, 0.5, 0.625, 0.75])  # texel centres at s = 0.25 and 0.75
    t = np.full(5, 0.5, np.float32)
    uv = np.stack([s, t], axis=1)
    linear = sample_texture(TextureData("float", two, extension="EXTEND", key="two"), uv)[:, 0]
    blended = sample_texture(TextureData("bytes", two, extension="EXTEND", key="two",
                                         srgb_bytes=True), uv)[:, 0]
    np.testing.assert_allclose(linear, [0, 0.25, 0.5, 0.75, 1], atol=2e-3)
    np.testing.assert_allclose(blended, srgb_to_linear([0, 0.25, 0.5, 0.75, 1]), atol=2e-3)
    assert blended[2] == pytest.approx(0.214, abs=3e-3)
    closest = sample_texture(TextureData("bytes", two, "Closest", "EXTEND", key="two",
                                         srgb_bytes=True), uv[[1, 3]])[:, 0]
    np.testing.assert_allclose(closest, [0, 1], atol=1e-3)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(s)), s, atol=1e-6)


def test_a_minified_byte_srgb_image_keeps_its_darker_blends():
    """The mip levels of a byte sRGB image hold the mean of what Cycles reads over their
    texels (the blends between texels included), so a minified lookup reads about what
    averaging many magnified lookups reads, darker than the texels' linear mean: of that
    difference, the levels miss at most 15% (their means take two points a texel per axis)."""
    pixels = checker(16, 4, dark=0.02, light=0.9)  # cells of 4 texels: half the texels on borders
    texture = TextureData("c", pixels, key="fine-checker", srgb_bytes=True)
    n = 256
    grid = (np.arange(n, dtype=np.float32) + 0.5) / n
    u, v = np.meshgrid(grid, grid)
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    magnified = sample_texture(texture, uv).mean(axis=0)
    levels = mip_pyramid(pixels, srgb_bytes=True)
    top = sample_texture(texture, uv[:1], lod=np.float32([len(levels) - 1]))[0]
    linear = pixels[..., :3].reshape(-1, 3).mean(axis=0)
    assert magnified[0] < 0.9 * linear[0]  # the blends read darker: 0.40 against 0.46
    assert np.abs(top - magnified).max() <= 0.15 * np.abs(linear - magnified).min()
    middle = sample_texture(texture, uv, lod=np.full(len(uv), 1.5, np.float32)).mean(axis=0)
    assert np.abs(middle - magnified).max() <= 0.15 * np.abs(linear - magnified).min()
    # the atlas says which textures hold encoded sRGB at level 0 (the GPU decodes those)
    atlas, table = pack_atlas((texture, TextureData("f", pixels, key="fine-checker")))
    assert table[0, 2, 1] == 1 and table[1, 2, 1] == 0
    x0, y0, w, h = table[0, 3].astype(int)
    np.testing.assert_allclose(atlas[y0:y0 + h, x0:x0 + w, :3], linear_to_srgb(pixels), atol=2e-3)


def textured_quad(size=2.0, uv_scale=1.0):
    """One textured quad (two triangles) of ``size`` metres in the z = 0 plane, UV 0…uv_scale."""
    positions = np.array([[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0]], np.float32)
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32) * uv_scale
    mesh = MeshData("quad", positions, triangles, np.zeros(2, np.int32), uvs=uv[triangles])
    material = MaterialData("tex", np.full(3, 0.5, np.float32), base_color_texture=0)
    texture = TextureData("c", checker(16, 4), extension="EXTEND", key="quad-checker")
    return SceneSnapshot(meshes={"quad": mesh}, materials=[material],
                         objects=[ObjectData("quad", "quad", np.eye(4))], textures=(texture,))


def test_surface_points_sample_their_texel():
    snapshot = textured_quad()
    tris = world_triangles(snapshot)
    assert tris.textures is not None
    # points at the centres of cell (0, 0) (light) and cell (1, 0) (dark), in triangle 0
    # (corners (0,0), (2,0), (2,2)): b1 = x − y, b2 = y over size 2
    points = np.array([[0.125, 0.1], [0.375, 0.1]]) * 2.0
    b2 = points[:, 1] / 2.0
    b1 = points[:, 0] / 2.0 - b2
    base = tris.textures.base_at(np.zeros(2, int), np.zeros(2, int), b1, b2, np.zeros((2, 3)))
    np.testing.assert_allclose(base[:, 0], [0.9, 0.1], atol=1e-3)
    # level-0 texels per metre: 16 texels over 2 m
    np.testing.assert_allclose(tris.textures.density, 8.0, rtol=1e-5)


def test_untextured_snapshots_carry_no_textures():
    snapshot = textured_quad()
    plain = SceneSnapshot(meshes=snapshot.meshes,
                          materials=[MaterialData("plain", np.full(3, 0.5, np.float32))],
                          objects=snapshot.objects)
    assert world_triangles(plain).textures is None


@pytest.mark.parametrize("span", [0.25, 1.0])
def test_voxel_albedo_follows_the_texture(span):
    """Voxels a cell wide take their cell's colour; voxels as large as the quad its mean."""
    snapshot = textured_quad(size=2.0)
    mesh = snapshot.meshes["quad"]
    positions = np.asarray(mesh.positions, np.float64)
    surface = voxelize_triangles(positions, mesh.triangles, span)
    sampler = texel_albedo(snapshot, mesh, positions)
    flat = np.full((2, 3), 0.5)
    attrs = average_attributes(surface, positions, mesh.triangles, flat, np.zeros(2),
                               texel_albedo=sampler)
    plain = average_attributes(surface, positions, mesh.triangles, flat, np.zeros(2))
    np.testing.assert_allclose(plain.albedo, 0.5, atol=1e-6)
    if span == 0.25:  # 8 × 8 voxels over 4 × 4 cells: each voxel inside one cell
        centre = (surface.cells[:, :2] + 0.5) * span  # roughly, in metres
        inside = (centre > 0.1).all(1) & (centre < 1.9).all(1)
        cell = np.floor(centre / 0.5).astype(int)
        expected = np.where((cell[:, 0] + cell[:, 1]) % 2 == 1, 0.1, 0.9)
        # the footprint of one voxel (2 texels: mip level 1) blurs each cell's edge by a texel
        error = np.abs(attrs.albedo[inside, 0] - expected[inside])
        assert error.max() < 0.15 and np.mean(error < 0.02) > 0.8
        assert attrs.albedo[:, 0].mean() == pytest.approx(0.5, abs=0.03)
    else:  # the voxels span 2 × 2 cells: the texture's mean
        np.testing.assert_allclose(attrs.albedo[:, 0], 0.5, atol=0.05)


def test_large_images_are_kept_within_the_largest_level():
    from voxgi.voxgi_addon.scene.textures import MAX_SIZE, within_max_size

    image = np.random.default_rng(1).random((8, 2 * MAX_SIZE + 3, 3)).astype(np.float32)
    kept = within_max_size(image)
    assert kept.dtype == np.float32 and max(kept.shape[:2]) <= MAX_SIZE
    # 4099 columns: padded to 4100 → 2050, still over → 1025; 8 rows → 4 → 2
    assert kept.shape == (2, MAX_SIZE // 2 + 1, 3)
    assert kept.mean() == pytest.approx(image.mean(), abs=2e-3)
    small = np.zeros((4, 4, 3), np.float32)
    assert within_max_size(small).shape == (4, 4, 3)

"""Alpha cut-outs (issue 22 point 2): rays pass a surface whose material's Alpha is below 1 in
proportion to 1 − Alpha, per texel (voxgi_addon/scene/textures.py ``cutout_hits``), in the
grid tracer (``raycast``) and the BVH traversal the GLSL ports (``bvh.traverse``) alike."""
import numpy as np
import pytest

from voxgi.voxgi_addon.scene import bvh, raycast
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import (
    MaterialData,
    MeshData,
    ObjectData,
    SceneSnapshot,
    TextureData,
)
from voxgi.voxgi_addon.scene.textures import cutout_random, pack_atlas


def mask_pixels(size=16, cells=4):
    """(size, size, 4) RGBA: a grey checker whose odd cells are fully transparent."""
    y, x = np.mgrid[0:size, 0:size]
    odd = ((x // (size // cells)) + (y // (size // cells))) % 2 == 1
    out = np.full((size, size, 4), 0.5, np.float32)
    out[..., 3] = np.where(odd, 0.0, 1.0)
    return out


def card_and_wall(alpha=1.0, alpha_texture=-1, textures=()):
    """A 2 × 2 m card at z = 1 (material 0, UV 0…1) over a 4 × 4 m wall at z = 0 (material 1)."""
    card = np.array([[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], np.float32)
    wall = np.array([[-1, -1, 0], [3, -1, 0], [3, 3, 0], [-1, 3, 0]], np.float32)
    quads = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    meshes = {"card": MeshData("card", card, quads, np.zeros(2, np.int32), uvs=uv[quads]),
              "wall": MeshData("wall", wall, quads, np.ones(2, np.int32), uvs=uv[quads])}
    materials = [MaterialData("card", np.full(3, 0.5, np.float32), alpha=alpha,
                              alpha_texture=alpha_texture,
                              base_color_texture=alpha_texture),
                 MaterialData("wall", np.array([0.8, 0.1, 0.1], np.float32))]
    objects = [ObjectData("card", "card", np.eye(4)), ObjectData("wall", "wall", np.eye(4))]
    return world_triangles(SceneSnapshot(meshes=meshes, materials=materials, objects=objects,
                                         textures=tuple(textures)))


def down_rays(n, seed=0, lo=0.05, hi=1.95):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(lo, hi, (n, 2))
    origins = np.column_stack([xy, np.full(n, 3.0)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    return origins, directions


def test_opaque_materials_make_no_cutouts():
    tris = card_and_wall()
    assert tris.textures is None  # nothing to test: the code of scenes without alpha


@pytest.mark.parametrize("alpha", [0.0, 0.3, 0.75])
def test_a_uniform_alpha_lets_rays_through_in_proportion(alpha):
    tris = card_and_wall(alpha=alpha)
    assert tris.textures.cutout.tolist() == [True, True, False, False]
    o, d = down_rays(20000)
    _, tri, _, _ = raycast.closest_hits(tris, o, d)
    on_card = np.isin(tri, [0, 1])
    assert on_card.mean() == pytest.approx(alpha, abs=0.015)
    assert np.isin(tri[~on_card], [2, 3]).all()  # what passes the card meets the wall
    # the BVH traversal (what bvh_common.glsl ports) makes the same decisions ray by ray
    _, tri_bvh, _, _ = bvh.closest_hits(tris, o, d)
    assert np.array_equal(tri, tri_bvh)
    # shadow rays between the card's two sides: blocked in proportion to the alpha
    blocked = raycast.occluded(tris, o, d, np.full(len(o), 2.5))
    assert blocked.mean() == pytest.approx(alpha, abs=0.015)
    assert np.array_equal(blocked, bvh.occluded(tris, o, d, np.full(len(o), 2.5)))


def test_an_alpha_texture_cuts_per_texel():
    texture = TextureData("mask", mask_pixels(), interpolation="Closest", extension="REPEAT",
                          key="mask")
    tris = card_and_wall(alpha_texture=0, textures=(texture,))
    o, d = down_rays(4000)
    _, tri, _, _ = raycast.closest_hits(tris, o, d)
    cell = (np.floor(o[:, 0] / 0.5) + np.floor(o[:, 1] / 0.5)) % 2 == 1  # transparent cells
    assert np.isin(tri[cell], [2, 3]).all()
    assert np.isin(tri[~cell], [0, 1]).all()
    _, tri_bvh, _, _ = bvh.closest_hits(tris, o, d)
    assert np.array_equal(tri, tri_bvh)


def test_the_hash_is_uniform_and_differs_per_ray_and_triangle():
    o, d = down_rays(50000, seed=3)
    u = cutout_random(o, d, np.zeros(len(o), int))
    assert 0.0 <= u.min() and u.max() < 1.0
    histogram = np.histogram(u, bins=10, range=(0, 1))[0] / len(u)
    np.testing.assert_allclose(histogram, 0.1, atol=0.01)
    other = cutout_random(o, d, np.ones(len(o), int))
    assert abs(np.corrcoef(u, other)[0, 1]) < 0.02


def test_the_atlas_holds_the_alpha_channel():
    rgba = TextureData("mask", mask_pixels(), key="mask-atlas")
    rgb = TextureData("plain", mask_pixels()[..., :3], key="plain-atlas")
    atlas, table = pack_atlas((rgba, rgb))
    x0, y0, w, h = table[0, 3].astype(int)
    np.testing.assert_array_equal(atlas[y0:y0 + h, x0:x0 + w, 3], mask_pixels()[..., 3])
    x0, y0, w, h = table[1, 3].astype(int)
    assert (atlas[y0:y0 + h, x0:x0 + w, 3] == 1.0).all()  # no alpha: opaque


def card_snapshot(alpha=1.0, alpha_texture=-1, textures=()):
    """The card of ``card_and_wall`` alone (the snapshot, for the voxelizer)."""
    card = np.array([[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], np.float32)
    quads = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    mesh = MeshData("card", card, quads, np.zeros(2, np.int32), uvs=uv[quads])
    material = MaterialData("card", np.full(3, 0.5, np.float32), alpha=alpha,
                            alpha_texture=alpha_texture)
    return SceneSnapshot(meshes={"card": mesh}, materials=[material],
                         objects=[ObjectData("card", "card", np.eye(4))], textures=tuple(textures))


def voxel_count(snapshot, span):
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    return len(build_scene_caches(snapshot, span, 1).caches["card"][0].positions)


def test_voxels_keep_a_cutouts_coverage():
    """Voxels a mask cell wide keep the opaque cells' voxels and drop the transparent ones';
    voxels of a uniform Alpha are kept in proportion (cones see through in proportion)."""
    texture = TextureData("mask", mask_pixels(), interpolation="Closest", key="mask-voxels")
    opaque = voxel_count(card_snapshot(), 0.125)
    masked = voxel_count(card_snapshot(alpha_texture=0, textures=(texture,)), 0.125)
    assert masked / opaque == pytest.approx(0.5, abs=0.08)
    half = voxel_count(card_snapshot(alpha=0.3), 0.0625)
    assert half / voxel_count(card_snapshot(), 0.0625) == pytest.approx(0.3, abs=0.05)
    assert voxel_count(card_snapshot(alpha=0.0), 0.125) == 0

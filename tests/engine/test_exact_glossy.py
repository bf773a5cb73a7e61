"""Exact one-bounce glossy reflections (voxgi_addon/gi/exact_glossy.py), the numpy reference of
shaders/bvh_glossy.glsl: energy under a uniform sky, mirrors, and what a glossy floor shows."""
import numpy as np
import pytest

from voxgi.voxgi_addon.gi.exact_glossy import glossy_indirect, vndf_half_vectors
from voxgi.voxgi_addon.scene.geometry import SceneTriangles

ANGLES = np.radians([0.0, 30.0, 45.0, 60.0, 75.0, 85.0])


def far_speck():
    """One tiny triangle far away: a scene whose rays all see the world."""
    corners = np.array([[[100.0, 100.0, 100.0], [100.1, 100.0, 100.0], [100.0, 100.1, 100.0]]])
    return SceneTriangles(corners, np.array([[0.0, 0.0, 1.0]]), np.array([-1], np.int32),
                          np.zeros(1, np.int32))


def views():
    return np.stack([np.sin(ANGLES), np.zeros_like(ANGLES), np.cos(ANGLES)], axis=1)


def floor_points():
    count = len(ANGLES)
    return np.zeros((count, 3)), np.tile([0.0, 0.0, 1.0], (count, 1))


@pytest.mark.parametrize("roughness", [0.05, 0.2, 0.5, 0.9])
@pytest.mark.parametrize("metallic", [0.0, 1.0])
def test_a_white_sky_reflects_as_one(roughness, metallic):
    """Under a uniform sky of radiance 1 the glossy light is the lobe's albedo, which Glossy
    Color is: Glossy Indirect = 1 for every roughness, metal or not, and view (the tables the
    colour and the BSDF come from agree to a few percent at grazing views)."""
    p, n = floor_points()
    principled = (np.array([[0.8, 0.5, 0.2], [1.0, 1.0, 1.0]]),
                  np.array([[metallic, 0.5, roughness], [0.0, 0.5, 0.5]]))
    value, variance = glossy_indirect(p, n, views(), np.zeros(len(p), int), np.arange(len(p)),
                                      far_speck(), [], principled, np.zeros((2, 3)), rays=2048,
                                      world=(1.0, 1.0, 1.0))
    assert value.shape == (len(p), 3) and variance.shape == (len(p),)
    np.testing.assert_allclose(value[ANGLES <= np.radians(60)], 1.0, atol=0.025)
    np.testing.assert_allclose(value, 1.0, atol=0.06)


def test_visible_normals_face_the_view_and_the_normal():
    rng = np.random.default_rng(3)
    v = views()
    h = vndf_half_vectors(v, np.full(len(v), 0.3), rng.random((len(v), 256, 2)))
    np.testing.assert_allclose(np.linalg.norm(h, axis=-1), 1.0, atol=1e-9)
    assert (h[..., 2] >= 0.0).all()
    assert (np.einsum("nkc,nc->nk", h, v) > -1e-9).all()  # visible from the view
    smooth = vndf_half_vectors(v, np.full(len(v), 1e-4), rng.random((len(v), 16, 2)))
    np.testing.assert_allclose(smooth[..., 2], 1.0, atol=1e-6)  # α → 0: the normal itself


def test_a_mirror_shows_the_lit_wall_and_a_rough_floor_blurs_it():
    """A floor facing a glowing wall 2 m away, 4 m high: a mirror floor (roughness 0) seen at 45° shows the
    wall's radiance exactly where its reflection lands on the wall and nothing where it
    misses; a rough floor spreads the wall over its lobe (some light either way)."""
    wall = np.array([[[-5.0, 2.0, -1.0], [5.0, 2.0, -1.0], [5.0, 2.0, 3.0]],
                     [[-5.0, 2.0, -1.0], [5.0, 2.0, 3.0], [-5.0, 2.0, 3.0]]])
    tris = SceneTriangles(wall, np.tile([0.0, -1.0, 0.0], (2, 1)), np.zeros(2, np.int32),
                          np.zeros(2, np.int32))
    emission = np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])  # the wall glows with radiance ½
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]])  # the second's reflection passes over it
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    v = np.tile([0.0, -np.sqrt(0.5), np.sqrt(0.5)], (2, 1))  # reflection heads for +y
    for roughness, expect in ((0.0, [0.5, 0.0]), (0.4, None)):
        principled = (np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]),
                      np.array([[1.0, 0.5, roughness], [0.0, 0.5, 0.5]]))
        value, _ = glossy_indirect(p, n, v, np.zeros(2, int), np.arange(2), tris, [], principled,
                                   emission, rays=256)
        if expect is not None:
            np.testing.assert_allclose(value[:, 0], expect, atol=1e-6)
        else:
            assert 0.05 < value[0, 0] < 0.5 and value[1, 0] < value[0, 0]


def test_no_rays_no_points_and_back_facing_views_give_zero():
    p, n = floor_points()
    principled = (np.ones((1, 3)), np.array([[0.0, 0.5, 0.5]]))
    empty, var = glossy_indirect(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), [], [],
                                 far_speck(), [], principled, np.zeros((1, 3)))
    assert empty.shape == (0, 3) and var.shape == (0,)
    below = -views()
    value, _ = glossy_indirect(p, n, below, np.zeros(len(p), int), np.arange(len(p)), far_speck(),
                               [], principled, np.zeros((1, 3)), rays=8, world=(1.0, 1.0, 1.0))
    assert not value.any()

"""The numpy references of the GPU exact-ray kernels: hashed strata in diffuse_direct, the light
table, and exact AO + one-bounce diffuse indirect (voxgi_addon/indirect.py)."""
import math

import numpy as np
import pytest
from meshes import box
from snapshots import mesh, snapshot

from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
from voxgi.voxgi_addon.gi.exact_indirect import cosine_directions, indirect_and_ao
from voxgi.voxgi_addon.gi.sampling import hammersley
from voxgi.voxgi_addon.preview.light_table import LIGHT_TEXELS, light_table
from voxgi.voxgi_addon.scene.geometry import SceneTriangles, world_triangles
from voxgi.voxgi_addon.scene.snapshot import LightData, ObjectData


def frame(position):
    m = np.eye(4)
    m[:3, 3] = position
    return m


def inward_box(size=2.0):
    """A closed cube of edge ``size`` centred on the origin, normals inwards."""
    positions, triangles = box((size, size, size))
    tris = world_triangles(snapshot([mesh("b", positions, np.asarray(triangles)[:, ::-1])],
                                    [ObjectData("B", "b", np.eye(4))]))
    return tris


def occluders():
    """A 1 m square roof at z = 1 over the origin (two triangles)."""
    c = np.array([[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0], [-0.5, 0.5, 1.0]])
    tri = np.stack([c[[0, 1, 2]], c[[0, 2, 3]]])
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    return SceneTriangles(tri, n, np.zeros(2, np.int32), np.zeros(2, np.int32))


def test_hashed_strata_follow_the_points_not_their_order():
    """With sample ids, a point's shadow samples depend on its id only: shuffling the points
    shuffles the result (the GPU shades pixels in any order)."""
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(-1.5, 1.5, (300, 2)), np.zeros(300)]
    n = np.tile([0.0, 0.0, 1.0], (300, 1))
    light = LightData("A", "AREA", np.ones(3, np.float32), 100.0, frame((0.3, 0.0, 2.0)), size=1.0)
    sun = LightData("S", "SUN", np.ones(3, np.float32), 3.0, frame((0, 0, 5)), angle=0.3)
    ids = np.arange(300) * 7 + 11
    a = diffuse_direct(p, n, [light, sun], occluders(), samples=16, sample_ids=ids)
    perm = rng.permutation(300)
    b = diffuse_direct(p[perm], n[perm], [light, sun], occluders(), samples=16, sample_ids=ids[perm])
    np.testing.assert_array_equal(a[perm], b)
    # Penumbrae exist and the generator's pattern agrees on average.
    c = diffuse_direct(p, n, [light, sun], occluders(), samples=16)
    assert 0 < (a[:, 0] < 0.9 * a[:, 0].max()).mean() < 1
    assert abs(a.sum() / c.sum() - 1) < 0.01


def test_light_table_rows():
    lights = [LightData("S", "SUN", np.ones(3, np.float32), 0.0, frame((0, 0, 1))),  # dark: left out
              LightData("P", "POINT", np.array([1, 0.5, 0.25], np.float32), 40.0, frame((1, 2, 3)), radius=0.1),
              LightData("D", "AREA", np.ones(3, np.float32), 10.0, frame((0, 0, 2)), size=0.5, shape="DISK")]
    table = light_table(lights)
    assert table.shape == (2, LIGHT_TEXELS, 4) and table.dtype == np.float32
    np.testing.assert_array_equal(table[0, 0], [1, 0, 0, 1])  # point, stream = list index 1
    np.testing.assert_allclose(table[0, 1], [1, 0.5, 0.25, 40.0])
    np.testing.assert_allclose(table[0, 2], [1, 2, 3, 0.1])
    assert table[1, 0, 0] == 3 and table[1, 0, 1] == 1 and table[1, 0, 2] == 64 and table[1, 0, 3] == 2
    area = math.pi * 0.25 * 0.25
    np.testing.assert_allclose(table[1, 6, :2], [area, 10.0 / (math.pi * area)], rtol=1e-6)
    np.testing.assert_allclose(table[1, 5, :3], [0, 0, -1])
    assert light_table([]).shape == (0, LIGHT_TEXELS, 4)


def test_cosine_directions_are_cosine_distributed():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = cosine_directions(n, hammersley(np.arange(200), 0, 64))
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    cos = np.einsum("nkc,nc->nk", d, n)
    assert (cos >= 0).all()
    assert abs(cos.mean() - 2.0 / 3.0) < 0.01  # E[cos θ] of the cosine distribution
    assert abs((cos ** 2).mean() - 0.5) < 0.01


def test_furnace_and_ao_inside_a_closed_box():
    """Inside a closed box whose walls glow with emission E (no lights), every ray meets a wall:
    Diffuse Indirect = E exactly, AO = 0 with a long AO distance and 1 with a tiny one."""
    tris = inward_box(2.0)
    rng = np.random.default_rng(2)
    p = rng.uniform(-0.8, 0.8, (50, 3))
    n = rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    albedo = np.array([[0.5, 0.5, 0.5], [0.8, 0.8, 0.8]])
    emission = np.array([[0.3, 0.2, 0.1], [0.0, 0.0, 0.0]])
    indirect, ao = indirect_and_ao(p, n, np.arange(50), tris, [], albedo, emission, rays=8,
                                   ao_distance=10.0)
    np.testing.assert_allclose(indirect, np.tile([0.3, 0.2, 0.1], (50, 1)), rtol=1e-6)
    np.testing.assert_array_equal(ao, 0.0)
    _, ao = indirect_and_ao(p, n, np.arange(50), tris, [], albedo, emission, rays=8,
                            ao_distance=0.01)
    np.testing.assert_array_equal(ao, 1.0)


def test_one_bounce_from_a_lit_floor():
    """A point light over a large white floor; the receiver faces down at height h: it sees the
    floor's Diffuse Direct × albedo, a known integral, and nothing on a miss (black world)."""
    size = 40.0
    c = np.array([[-size, -size, 0.0], [size, -size, 0.0], [size, size, 0.0], [-size, size, 0.0]])
    tris = SceneTriangles(np.stack([c[[0, 1, 2]], c[[0, 2, 3]]]), np.tile([0.0, 0.0, 1.0], (2, 1)),
                          np.zeros(2, np.int32), np.zeros(2, np.int32))
    light = LightData("P", "POINT", np.ones(3, np.float32), 1000.0, frame((0, 0, 1.0)))
    albedo = np.array([[0.5, 0.5, 0.5], [0.8, 0.8, 0.8]])
    emission = np.zeros((2, 3))
    h = 0.5
    p = np.array([[0.0, 0.0, h]])
    indirect, ao = indirect_and_ao(p, [[0.0, 0.0, -1.0]], [0], tris, [light], albedo, emission,
                                   rays=4096, ao_distance=0.1)
    # Floor point at radius r: E/π = P/(4π) · cos / d² / π with d² = 1 + r², cos = 1/d; the
    # receiver at height h sees it with ∫ L cos/π dω = ∫ L h² / (π s⁴) dA, s² = h² + r².
    r = np.linspace(0, size, 400001)
    direct = 1000.0 / (4 * math.pi) / (1 + r ** 2) ** 1.5 / math.pi
    expected = 0.5 * np.trapz(direct * h * h / (math.pi * (h * h + r * r) ** 2) * 2 * math.pi * r, r)
    assert abs(indirect[0, 0] / expected - 1) < 0.02
    assert ao[0] == 1.0  # the floor is 0.5 m away, beyond the AO distance


@pytest.mark.parametrize("metallic", [0.0, 1.0])
def test_a_glossy_wall_reflects_the_lit_part_of_an_area_light_whose_centre_is_behind_it(metallic):
    """A glossy wall (black Base Color: its glossy lobe alone) under a ceiling light whose centre
    lies behind the wall's plane while a strip of it lights the wall's face: a bounce hit's
    glossy lobe reflects that strip toward the receiver facing the wall (it reflected nothing
    when it looked at the light's centre, below the wall's horizon). Against brute force
    (cosine rays to the wall, the hit's Principled glossy lobe integrated over the light): a
    dielectric hit evaluates its lobe toward one direction, the lit strip's middle, which reads
    0.61 of it here (a lobe of roughness 0.3 across a strip 1 m wide; the bound is half to
    1.5 ×, which reading the light's centre, 0, fails); a metal's lobe is integrated over the
    light (LTC, exact_indirect._area_shine): within 6% (0.958 measured; one direction read
    0.62)."""
    from voxgi.voxgi_addon.gi.principled import glossy_reflectance

    # the wall: y = 0, x in [-2, 2], z in [0, 1.5], facing -y
    c = np.array([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 0.0, 1.5], [-2.0, 0.0, 1.5]])
    tris = SceneTriangles(np.stack([c[[0, 1, 2]], c[[0, 2, 3]]]), np.tile([0.0, -1.0, 0.0], (2, 1)),
                          np.zeros(2, np.int32), np.zeros(2, np.int32))
    # a 1 m square light at z = 2 facing down, its centre 0.3 m behind the wall's plane
    light = LightData("A", "AREA", np.ones(3, np.float32), 200.0, frame((0.0, 0.3, 2.0)), size=1.0)
    base = np.full((2, 3), 0.0 if metallic < 0.5 else 0.9)  # a metal's colour is its Base Color
    params = np.tile([[metallic, 0.5, 0.3]], (2, 1))  # metallic, Specular IOR Level, roughness
    emission = np.zeros((2, 3))
    p = np.array([[0.0, -0.6, 0.4]])
    n = np.array([[0.0, 1.0, 0.0]])
    ours, _ = indirect_and_ao(p, n, [0], tris, [light], (base, params), emission, rays=2048,
                              hit_glossy=True, hit_samples=16)
    # brute force
    rng = np.random.default_rng(3)
    u = rng.random((4096, 2))
    r, phi = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
    d = np.stack([r * np.cos(phi), np.sqrt(1.0 - u[:, 0]), r * np.sin(phi)], axis=1)
    t = 0.6 / d[:, 1]
    x = p + t[:, None] * d
    on_wall = (np.abs(x[:, 0]) <= 2.0) & (x[:, 2] >= 0.0) & (x[:, 2] <= 1.5)
    x, d = x[on_wall], d[on_wall]
    k = 256
    square = (rng.random((len(x), k, 2)) - 0.5)
    on_light = np.array([0.0, 0.3, 2.0]) + np.stack([square[..., 0], square[..., 1],
                                                     np.zeros(square.shape[:2])], axis=-1)
    w = on_light - x[:, None]
    r2 = (w * w).sum(-1)
    wd = w / np.sqrt(r2)[..., None]
    cos_l = np.maximum(wd[..., 2], 0.0)  # the light faces down
    f = glossy_reflectance(np.full((len(x), k, 3), 0.0 if metallic < 0.5 else 0.9), metallic, 0.5, 0.3,
                           np.broadcast_to([0.0, -1.0, 0.0], wd.shape), -d[:, None], wd)
    radiance = 200.0 / math.pi * (f * (cos_l / r2)[..., None]).mean(axis=1)  # L · A = P / π
    expected = radiance.sum(axis=0) / 4096
    print(f"glossy wall, metallic {metallic}: ours {ours[0]}, brute force {expected}")
    assert expected[0] > 0.005
    if metallic < 0.5:
        assert 0.5 < ours[0, 0] / expected[0] < 1.5
    else:
        assert abs(ours[0, 0] / expected[0] - 1.0) < 0.06

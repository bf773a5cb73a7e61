"""One lamp a bounce hit (``exact_indirect.lamp_picks``, GLSL ``bvh_shade.glsl`` ray_paths): a
hit traces the shadow rays of one lamp picked by its unshadowed light, its light divided by
its chance, so that a hit's cost does not grow with the lamps; the gathered light keeps its
mean (docs/gi_pipeline.md "One lamp a bounce hit")."""
import numpy as np
import pytest

from voxgi.voxgi_addon.gi import exact_indirect
from voxgi.voxgi_addon.gi.exact_indirect import LAMP_PICK_FLOOR, indirect_and_ao, lamp_picks
from voxgi.voxgi_addon.scene.geometry import SceneTriangles
from voxgi.voxgi_addon.scene.snapshot import LightData


def frame(position):
    m = np.eye(4)
    m[:3, 3] = position
    return m


def floor(size=40.0):
    c = np.array([[-size, -size, 0.0], [size, -size, 0.0], [size, size, 0.0], [-size, size, 0.0]])
    return SceneTriangles(np.stack([c[[0, 1, 2]], c[[0, 2, 3]]]), np.tile([0.0, 0.0, 1.0], (2, 1)),
                          np.zeros(2, np.int32), np.zeros(2, np.int32))


def lamps():
    """Three point lamps of different power and place, and a sun, over the floor."""
    white = np.ones(3, np.float32)
    sun = np.eye(4)
    sun[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.8, -0.6], [0.0, 0.6, 0.8]]  # shining down and along y
    return [LightData("P1", "POINT", white, 600.0, frame((0.0, 0.0, 1.0))),
            LightData("P2", "POINT", np.array([1.0, 0.6, 0.3], np.float32), 250.0,
                      frame((1.5, -0.5, 1.5)), radius=0.2),
            LightData("P3", "POINT", white, 80.0, frame((-1.0, 1.0, 0.6))),
            LightData("Sun", "SUN", white, 1.5, sun)]


def every_lamp(monkeypatch):
    """ray_paths as before the picks: every lamp traced at every hit."""
    monkeypatch.setattr(exact_indirect, "lamp_picks", lambda *args, **kwargs: None)


@pytest.mark.parametrize("receiver", [(0.0, 0.0, 0.5), (1.2, 0.8, 0.3)])
def test_one_lamp_a_hit_gathers_the_light_of_them_all(monkeypatch, receiver):
    """A receiver facing a floor lit by three point lamps and a sun: the gather with one lamp a
    hit reads what it reads with every lamp at every hit, within the picks' noise over 4,096
    rays — and it does pick (its rays differ)."""
    tris, lights = floor(), lamps()
    albedo = np.array([[0.5, 0.5, 0.5], [0.8, 0.8, 0.8]])
    emission = np.zeros((2, 3))
    p, n = np.array([receiver]), np.array([[0.0, 0.0, -1.0]])
    picked, _ = indirect_and_ao(p, n, [0], tris, lights, albedo, emission, rays=4096,
                                ao_distance=0.1, seed=5)
    with monkeypatch.context() as m:
        every_lamp(m)
        whole, _ = indirect_and_ao(p, n, [0], tris, lights, albedo, emission, rays=4096,
                                   ao_distance=0.1, seed=5)
    assert whole[0].min() > 0.05
    assert np.abs(picked[0] / whole[0] - 1.0).max() < 0.03, (picked, whole)
    assert not np.allclose(picked, whole)


def test_lamps_are_picked_by_their_light_and_none_is_left_out():
    """Over many hits at one point: each lamp is picked as often as its chance says; a lamp
    that sheds nothing there (below the point's horizon) still gets its floor share, and the
    brightest gets the most."""
    lights = lamps()[:3]
    count = 20000
    points = np.tile([[0.2, 0.1, 0.0]], (count, 1))
    normals = np.tile([[0.0, 0.0, 1.0]], (count, 1))
    lights[2] = LightData("Below", "POINT", np.ones(3, np.float32), 80.0, frame((-1.0, 1.0, -0.5)))
    picked, chance = lamp_picks(lights, points, normals, np.arange(count), 7)
    share = np.bincount(picked, minlength=3) / count
    floor_share = LAMP_PICK_FLOOR / 3
    assert share[2] == pytest.approx(floor_share, abs=0.01)  # unlit: the floor share alone
    assert np.allclose(chance[picked == 2], floor_share)
    assert share[0] > share[1] > share[2]
    for k in range(3):  # the frequencies are the chances
        assert share[k] == pytest.approx(chance[picked == k][0], abs=0.015)


def test_a_single_lamp_is_traced_at_every_hit():
    lights = lamps()[:1]
    assert lamp_picks(lights, np.zeros((4, 3)), np.tile([[0.0, 0.0, 1.0]], (4, 1)),
                      np.arange(4), 1) is None


def test_a_metal_hit_picks_the_lamps_by_what_its_lobe_reflects(monkeypatch):
    """A metal floor whose glossy lobe the hits take: its light is the lobe's, so its picks
    weigh each lamp by what the lobe sends toward the receiver; the gather reads what it reads
    with every lamp at every hit, within the picks' noise over 4,096 rays, and it picks."""
    tris, lights = floor(), lamps()
    base = np.full((2, 3), 0.9)
    params = np.tile([[1.0, 0.5, 0.3]], (2, 1))  # metallic, Specular IOR Level, roughness
    emission = np.zeros((2, 3))
    p, n = np.array([[0.3, -0.2, 0.6]]), np.array([[0.0, 0.0, -1.0]])
    ours, _ = indirect_and_ao(p, n, [0], tris, lights, (base, params), emission, rays=4096,
                              ao_distance=0.1, seed=2, hit_glossy=True)
    with monkeypatch.context() as m:
        every_lamp(m)
        whole, _ = indirect_and_ao(p, n, [0], tris, lights, (base, params), emission,
                                   rays=4096, ao_distance=0.1, seed=2, hit_glossy=True)
    assert whole[0].max() > 0.01
    assert np.abs(ours[0] / whole[0] - 1.0).max() < 0.03, (ours, whole)
    assert not np.allclose(ours, whole)


@pytest.mark.parametrize("aimed", [True, False])
def test_a_spot_is_picked_by_the_light_its_cone_sends(aimed):
    """A spot over the floor beside a point lamp: aimed at the floor it takes most picks there;
    turned up to the ceiling (the floor outside its cone) the floor share alone."""
    count = 4000
    points = np.tile([[0.0, 0.0, 0.0]], (count, 1))
    normals = np.tile([[0.0, 0.0, 1.0]], (count, 1))
    m = frame((0.0, 0.0, 1.0))
    if not aimed:
        m[:3, :3] = np.diag([1.0, -1.0, -1.0])  # its -Z (where it shines) turned up
    spot = LightData("S", "SPOT", np.ones(3, np.float32), 600.0, m, spot_size=0.8, spot_blend=0.2)
    lights = [lamps()[2], spot]
    picked, chance = lamp_picks(lights, points, normals, np.arange(count), 3)
    share = np.bincount(picked, minlength=2)[1] / count
    if aimed:
        assert share > 0.8
    else:
        assert share == pytest.approx(LAMP_PICK_FLOOR / 2, abs=0.02)
        assert np.allclose(chance[picked == 1], LAMP_PICK_FLOOR / 2)

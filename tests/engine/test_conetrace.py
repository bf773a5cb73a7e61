"""Cone tracing on analytic volumes: empty space, an enclosing glowing shell, a blocker."""
import numpy as np
import pytest

from volumes import DenseMipVolume
from voxgi_addon.conetrace import (ConeSettings, diffuse_cone_set, trace_diffuse_and_ao,
                                   trace_glossy, trace_shadow)

R = 64
SIZE = 8.0  # a 8 m cube centred at the origin, voxels of 0.125 m


def grid_centres():
    c = (np.arange(R) + 0.5) / R * SIZE - SIZE / 2
    return np.stack(np.meshgrid(c, c, c, indexing="ij"), axis=-1)


def shell_volume(radius, thickness=0.25, radiance=(0.5, 0.25, 1.0)):
    dist = np.linalg.norm(grid_centres(), axis=-1)
    occupied = np.abs(dist - radius) <= thickness / 2
    rad = np.broadcast_to(np.asarray(radiance, float), (R, R, R, 3)).copy()
    return DenseMipVolume(occupied, rad, [-SIZE / 2] * 3, SIZE)


def probe_points(count=16, seed=0):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(count, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    points = rng.uniform(-0.3, 0.3, size=(count, 3))
    return points, normals


def test_cone_weights_integrate_uniform_radiance_to_itself():
    dirs, weights = diffuse_cone_set(6, np.radians(30))
    assert weights.sum() == pytest.approx(1.0)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0) and (dirs[:, 2] > 0).all()


def test_empty_space_is_dark_and_unoccluded():
    vol = DenseMipVolume(np.zeros((R, R, R), bool), np.zeros((R, R, R, 3)), [-4] * 3, SIZE)
    points, normals = probe_points()
    diffuse, ao = trace_diffuse_and_ao(vol, points, normals, ConeSettings())
    assert np.abs(diffuse).max() == 0.0 and np.allclose(ao, 1.0)


def test_inside_a_glowing_shell_diffuse_equals_its_radiance_and_ao_sees_the_distance():
    vol = shell_volume(radius=3.0)
    points, normals = probe_points()
    # A two-voxel shell read at coarse levels is half-transparent ("present children / 8");
    # opacity_scale 2 makes it opaque again, and then no light is lost.
    settings = ConeSettings(ao_distance=1.0, opacity_scale=2.0)
    diffuse, ao = trace_diffuse_and_ao(vol, points, normals, settings)
    # Uniform incoming radiance L gives irradiance/π = L (Cycles' Diffuse Indirect units).
    assert np.abs(diffuse / [0.5, 0.25, 1.0] - 1.0).max() < 0.15
    assert ao.min() > 0.95  # the shell is 3 m away, beyond the 1 m AO distance
    _, ao_near = trace_diffuse_and_ao(vol, points, normals,
                                      ConeSettings(ao_distance=4.0, opacity_scale=2.0))
    assert ao_near.max() < 0.1


def test_glossy_mirror_sees_the_wall_it_faces_and_shadow_cone_sees_a_blocker():
    centres = grid_centres()
    wall = np.abs(centres[..., 0] - 2.0) < 0.13  # a glowing wall at x = 2
    rad = np.zeros((R, R, R, 3))
    rad[wall] = [2.0, 1.0, 0.5]
    vol = DenseMipVolume(wall, rad, [-4] * 3, SIZE)
    p = np.zeros((1, 3))
    n = np.array([[1.0, 0.0, 0.0]])
    view = np.array([[-1.0, 0.0, 0.0]])  # looking back at the point along -x: mirror is +x
    glossy = trace_glossy(vol, p, n, view, roughness=np.array([0.05]), settings=ConeSettings())
    assert np.allclose(glossy[0], [2.0, 1.0, 0.5], rtol=0.15)
    blocked = trace_shadow(vol, p, n, np.array([[3.5, 0.0, 0.0]]), 0.1, ConeSettings())
    free = trace_shadow(vol, p, n, np.array([[0.0, 0.0, 3.5]]), 0.1, ConeSettings())
    assert blocked[0] < 0.05 and free[0] > 0.99


def test_settings_reject_nonsense():
    with pytest.raises(ValueError, match="cone angle"):
        ConeSettings(cone_angle=0.0)
    with pytest.raises(ValueError, match="positive"):
        ConeSettings(ao_distance=0.0)

"""Cycles' shadow terminator offset (voxgi_addon/gi/terminator.py): a smooth-shaded
triangle's shadow rays leave from the smooth surface its vertex normals describe."""
from __future__ import annotations

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.terminator import OFFSET, ShadowStarts, amount, lift


def _sphere_triangle(size: float):
    """A triangle with its corners on the unit sphere about +Z (``size`` radians apart) and the
    sphere's radial normals at them."""
    angles = (0.0, 2.0 * np.pi / 3.0, 4.0 * np.pi / 3.0)
    corners = np.array([[np.sin(size) * np.cos(a), np.sin(size) * np.sin(a), np.cos(size)]
                        for a in angles])
    return corners, corners.copy()


def test_a_flat_triangle_is_not_lifted():
    corners = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    out = lift(corners[None], normals[None], [0.3], [0.2], [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(out, 0.0, atol=1e-15)


@pytest.mark.parametrize("size", [0.1, 0.3])
def test_a_sphere_triangle_is_lifted_to_its_corners_tangent_planes(size):
    """At the middle of a triangle inscribed in a sphere the lift reaches the lowest of its
    corners' tangent planes (the envelope: it lies above the parabola's half there), along the
    interpolated vertex normal (outward) — twice the sphere's own height over that point, as
    Cycles lifts it."""
    corners, normals = _sphere_triangle(size)
    ng = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    ng /= np.linalg.norm(ng)
    middle = corners.mean(axis=0)
    out = lift(corners[None], normals[None], [1.0 / 3.0], [1.0 / 3.0], ng[None])[0]
    to_planes = 1.0 - middle @ corners[0]  # each corner's plane over the middle (all equal)
    np.testing.assert_allclose(out, middle * to_planes, rtol=1e-9, atol=1e-15)  # normal × h
    assert to_planes == pytest.approx(2.0 * (1.0 - np.linalg.norm(middle)), rel=0.03)
    assert out @ ng > 0.0
    # at a corner the triangle touches the sphere: nothing to lift
    at_corner = lift(corners[None], normals[None], [0.0], [0.0], ng[None])[0]
    assert np.linalg.norm(at_corner) < 1e-12


def test_only_nearly_grazing_rays_take_the_lift():
    n = ng = np.array([0.0, 0.0, 1.0])
    up = np.array([0.0, 0.0, 1.0])
    grazing = np.array([1.0, 0.0, 0.0])
    assert amount(n, ng, up) == 0.0
    assert amount(n, ng, grazing) == 1.0
    tilted = np.array([np.cos(0.15), 0.0, np.sin(0.15)])  # 0.15 above the plane, past 0.1
    assert 0.0 < amount(n, ng, tilted) < 1.0 or amount(n, ng, tilted) == 0.0
    assert amount(n, ng, np.array([np.cos(0.3), 0.0, np.sin(0.3)])) == 0.0  # past 2 × offset
    assert OFFSET == 0.1  # Cycles' default Geometry Offset


def test_shadow_starts_move_each_ray_by_its_points_lift():
    """The occluder a lifted diffuse_direct traces through: a ray from a listed start leaves
    from there plus its share of that point's lift (toward a point it keeps its end); a ray
    from elsewhere is left as it is."""
    seen = []

    class Record:
        def occluded(self, origins, directions, max_t):
            seen.append((np.array(origins), np.array(directions), np.array(max_t)))
            return np.zeros(len(origins), bool)

    starts = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    normals = np.tile([0.0, 0.0, 1.0], (2, 1))
    lifts = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.02]])
    occluder = ShadowStarts(Record(), starts, normals, lifts, normals)
    dirs = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    occluder.occluded(np.array([[5.0, 0.0, 0.0], [9.0, 9.0, 9.0], [0.0, 0.0, 0.0]]), dirs,
                      np.array([2.0, np.inf, np.inf]))
    origins, directions, lengths = seen[0]
    np.testing.assert_allclose(origins[0], [5.0, 0.0, 0.02])  # grazing: all of it
    end = origins[0] + directions[0] * lengths[0]
    np.testing.assert_allclose(end, [7.0, 0.0, 0.0], atol=1e-12)  # the same end
    np.testing.assert_allclose(origins[1], [9.0, 9.0, 9.0])  # not a listed start
    np.testing.assert_allclose(origins[2], [0.0, 0.0, 0.0])  # straight up: none of it

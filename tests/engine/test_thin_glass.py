"""scene.glass and preview.transmission: thin glass lets the view and light through (no bpy)."""
from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from voxgi.voxgi_addon.preview.transmission import behind_glass, composite, glass_weight
from voxgi.voxgi_addon.scene.geometry import SceneTriangles
from voxgi.voxgi_addon.scene.glass import (
    camera_transmittance,
    fresnel_dielectric,
    ray_alpha,
    slab_transmittance,
)
from voxgi.voxgi_addon.scene.snapshot import RAY_CAMERA, RAY_SHADOW, MaterialData


def glass(color=(1.0, 1.0, 1.0), ior=1.5, alpha=1.0):
    return MaterialData(name="Glass", base_color=np.zeros(3, np.float32), roughness=0.0,
                        transmission=np.asarray(color, np.float32), ior=ior, alpha=alpha)


def test_fresnel_of_glass_at_normal_and_grazing_incidence():
    assert abs(float(fresnel_dielectric(1.0, 1.5)) - 0.04) < 1e-9  # ((n-1)/(n+1))²
    assert float(fresnel_dielectric(0.0, 1.5)) > 0.999
    # Brewster's angle: the p-polarized half vanishes, the mean is half the s one
    cos_b = np.cos(np.arctan(1.5))
    sin_t = np.sin(np.arctan(1.5)) / 1.5
    cos_t = np.sqrt(1 - sin_t ** 2)
    rs = ((cos_b - 1.5 * cos_t) / (cos_b + 1.5 * cos_t)) ** 2
    assert abs(float(fresnel_dielectric(cos_b, 1.5)) - rs / 2) < 1e-9


@given(st.floats(0.0, 1.0), st.floats(1.0, 3.0))
def test_a_slab_passes_what_it_does_not_reflect(cos, ior):
    f = float(fresnel_dielectric(cos, ior))
    t = float(slab_transmittance(cos, ior))
    reflected = f + (1 - f) ** 2 * f / (1 - f * f) if f < 1 else 1.0  # both faces, all orders
    assert 0.0 <= t <= 1.0
    assert abs(t + reflected - 1.0) < 1e-9


def test_clear_glass_passes_92_percent_at_normal_incidence():
    assert abs(float(slab_transmittance(1.0, 1.5)) - 0.96 / 1.04) < 1e-12
    assert abs(ray_alpha(glass()) - (1 - 0.96 / 1.04)) < 1e-6
    tinted = ray_alpha(glass((0.2, 0.8, 0.5)))  # rays pass the tint's mean share
    assert abs(tinted - (1 - 0.5 * 0.96 / 1.04)) < 1e-6
    opaque = MaterialData(name="Wall", base_color=np.ones(3, np.float32), alpha=0.4)
    assert ray_alpha(opaque) == 0.4  # a cut-out's own Alpha, nothing else


def test_camera_sees_through_in_colour_and_by_angle():
    materials = [MaterialData(name="Wall", base_color=np.ones(3, np.float32)),
                 glass((0.5, 1.0, 0.25))]
    w = camera_transmittance(materials, np.array([0, 1, 1, -1]), np.array([1.0, 1.0, 0.1, 1.0]))
    assert np.all(w[0] == 0) and np.all(w[3] == 0)
    assert np.allclose(w[1], np.array([0.5, 1.0, 0.25]) * 0.96 / 1.04)
    assert np.all(w[2] < 0.5 * w[1])  # grazing: mostly reflected


def test_behind_glass_hides_glass_from_camera_rays_only():
    tris = SceneTriangles(positions=np.zeros((3, 3, 3)), normals=np.zeros((3, 3)),
                          materials=np.array([0, 1, 1], np.int32), objects=np.zeros(3, np.int32))
    behind = behind_glass(tris, np.array([1]))
    assert behind.accepted(RAY_CAMERA).tolist() == [True, False, False]
    assert behind.accepted(RAY_SHADOW) is None
    assert tris.visibility is None  # the front layer's triangles are untouched


def test_glass_weight_filters_the_silhouette():
    """A pane covering the left half of a pixel column: the centre samples say all or
    nothing, the sub-pixel offsets give the edge pixels a share between."""
    materials = [MaterialData(name="Wall", base_color=np.ones(3, np.float32)), glass()]
    width, height, edge_x = 8, 4, 4.3  # the pane's edge crosses pixel column 4

    def hits_at(offset):
        x = np.arange(width)[None, :] + 0.5 + offset[0]
        material = np.where(np.broadcast_to(x, (height, width)) < edge_x, 1, 0)
        return material, np.ones((height, width))

    point = glass_weight(materials, hits_at, width, height, filter_width=0.0)
    assert np.allclose(np.unique(point[..., 0]), [0.0, 0.96 / 1.04])
    filtered = glass_weight(materials, hits_at, width, height)
    full = 0.96 / 1.04
    assert np.allclose(filtered[:, :3], full, atol=2e-3)  # inside: the slab's share
    assert np.allclose(filtered[:, 6:], 0.0, atol=1e-6)
    share = filtered[0, 4, 0] / full  # about 0.3 of pixel 4 is glass
    assert 0.1 < share < 0.5, share


def test_composite_adds_what_is_behind_and_the_world_where_nothing_is():
    front = {"Combined": np.full((1, 2, 3), 0.1, np.float32), "Diffuse Color": np.zeros((1, 2, 3))}
    behind = {"Combined": np.array([[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]], np.float32),
              "Alpha": np.array([[1.0, 0.0]], np.float32)}
    weight = np.full((1, 2, 3), 0.5, np.float32)
    sky = np.full((1, 2, 3), 4.0, np.float32)
    out = composite(front, behind, weight, sky)
    assert np.allclose(out["Combined"][0, 0], 0.1 + 0.5 * 1.0)
    assert np.allclose(out["Combined"][0, 1], 0.1 + 0.5 * 4.0)  # the sky through the glass
    assert out["Diffuse Color"] is front["Diffuse Color"]

"""Roughness and Metallic per texel (issue 18 point 2): a material with a parameter texture is
followed by its variants at quantized values, and what the camera sees shades as the variant
of its texel (voxgi_addon/scene/textures.py ``SurfaceTextures.variant_at``)."""
import dataclasses

import numpy as np

from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.raycast import primary_visibility
from voxgi.voxgi_addon.scene.snapshot import (
    CameraData,
    MaterialData,
    MeshData,
    ObjectData,
    SceneSnapshot,
    TextureData,
)
from voxgi.voxgi_addon.scene.textures import (
    METALLIC_LEVELS,
    PARAM_VARIANTS,
    ROUGHNESS_LEVELS,
    variant_of,
    variant_values,
)


def test_variants_cover_the_quantized_values():
    index = np.arange(PARAM_VARIANTS)
    rough, metal = variant_values(index)
    assert np.array_equal(variant_of(rough, metal), index)
    np.testing.assert_allclose(np.unique(np.round(rough, 6)), np.linspace(0, 1, ROUGHNESS_LEVELS),
                               atol=1e-6)
    np.testing.assert_allclose(np.unique(np.round(metal, 6)), np.linspace(0, 1, METALLIC_LEVELS),
                               atol=1e-6)
    # the nearest variant, values clipped
    assert variant_of([0.34, 1.7], [0.9, -1.0]).tolist() == [3 * ROUGHNESS_LEVELS + 5,
                                                             ROUGHNESS_LEVELS - 1]


def params_pixels(size=16):
    """Left half polished metal (roughness 0.2, metallic 1), right half rough (0.8, 0)."""
    out = np.zeros((size, size, 4), np.float32)
    left = np.arange(size) < size // 2
    out[:, left, 0], out[:, left, 1] = 0.2, 1.0
    out[:, ~left, 0], out[:, ~left, 1] = 0.8, 0.0
    out[..., 3] = 1.0
    return out


def textured_quad_snapshot():
    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    mesh = MeshData("quad", positions, triangles, np.zeros(2, np.int32), uvs=uv[triangles])
    base = MaterialData("mr", np.full(3, 0.6, np.float32), roughness=0.5, metallic=0.5,
                        param_texture=0, param_variants=1)
    materials = [base] + [dataclasses.replace(base, name=f"mr {k}", roughness=float(r),
                                              metallic=float(m), param_texture=-1,
                                              param_variants=-1)
                          for k, (r, m) in enumerate(zip(*variant_values(np.arange(PARAM_VARIANTS))))]
    texture = TextureData("mr", params_pixels(), interpolation="Closest", extension="EXTEND",
                          key="params")
    # an orthographic camera 2 m above, looking down at the quad
    world = np.eye(4)
    world[2, 3] = 2.0
    camera = CameraData("cam", world, np.eye(4), (16, 16), type="ORTHO", ortho_scale=1.6,
                        clip_start=0.1, clip_end=10.0)
    return SceneSnapshot(meshes={"quad": mesh}, materials=materials,
                         objects=[ObjectData("quad", "quad", np.eye(4))], camera=camera,
                         textures=(texture,))


def test_the_camera_sees_each_texels_variant():
    snapshot = textured_quad_snapshot()
    tris = world_triangles(snapshot)
    seen = primary_visibility(tris, snapshot.camera, 16, 16)
    assert seen.hit.all()
    left = seen.position[..., 0] < -0.05
    right = seen.position[..., 0] > 0.05
    materials = snapshot.materials
    rough = np.array([m.roughness for m in materials])[seen.material]
    metal = np.array([m.metallic for m in materials])[seen.material]
    np.testing.assert_allclose(rough[left], 0.2, atol=0.5 / (ROUGHNESS_LEVELS - 1))
    np.testing.assert_allclose(metal[left], 1.0)
    np.testing.assert_allclose(rough[right], 0.8, atol=0.5 / (ROUGHNESS_LEVELS - 1))
    np.testing.assert_allclose(metal[right], 0.0)
    # the triangles keep the material itself (bounce hits shade with its means)
    assert (np.asarray(tris.materials) == 0).all()


def test_face_tangents_follow_the_uv_map():
    from voxgi.voxgi_addon.scene.textures import face_tangents

    p = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]]], np.float64)
    uv = np.array([[[0, 0], [1, 0], [1, 1]]], np.float64)
    np.testing.assert_allclose(face_tangents(p, uv), [[1, 0, 0, 1]], atol=1e-6)
    mirrored = uv.copy()
    mirrored[..., 0] *= -1.0  # u runs along −x: the tangent turns, v still along +y
    np.testing.assert_allclose(face_tangents(p, mirrored), [[-1, 0, 0, -1]], atol=1e-6)
    flat = np.zeros_like(uv)  # no UV map: no tangent
    np.testing.assert_allclose(face_tangents(p, flat)[:, :3], 0.0)


def test_normal_maps_perturb_as_cycles_normal_map_node():
    from voxgi.voxgi_addon.scene.textures import perturbed_normals

    n = np.array([[0.0, 0.0, 1.0]] * 4)
    t = np.array([[1.0, 0.0, 0.0, 1.0]] * 4)
    colour = np.array([[0.5, 0.5, 1.0], [1.0, 0.5, 0.5], [0.5, 1.0, 0.5], [1.0, 0.5, 0.5]])
    out = perturbed_normals(n, t, colour, np.array([1.0, 1.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, [[0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], atol=1e-9)
    # half strength: halfway between the normal and the mapped one, normalised
    half = perturbed_normals(n[:1], t[:1], colour[1:2], np.array([0.5]))
    np.testing.assert_allclose(half, [[np.sqrt(0.5), 0, np.sqrt(0.5)]], atol=1e-9)
    # a negative bitangent sign mirrors the map's y
    mirrored = perturbed_normals(n[:1], np.array([[1.0, 0, 0, -1.0]]), colour[2:3], np.ones(1))
    np.testing.assert_allclose(mirrored, [[0, -1, 0]], atol=1e-9)


def test_the_camera_sees_normal_mapped_shading_normals():
    snapshot = textured_quad_snapshot()
    lean = np.zeros((4, 4, 3), np.float32)
    lean[:, :2] = [0.85, 0.5, 0.85]    # left half leans towards +x (tangent = +u = +x)
    lean[:, 2:] = [0.5, 0.5, 1.0]      # right half flat
    materials = [dataclasses.replace(m, normal_texture=1, normal_strength=1.0)
                 for m in snapshot.materials]
    snapshot = dataclasses.replace(snapshot, materials=materials, textures=snapshot.textures + (
        TextureData("lean", lean, interpolation="Closest", extension="EXTEND", key="lean"),))
    seen = primary_visibility(world_triangles(snapshot), snapshot.camera, 16, 16)
    left = seen.position[..., 0] < -0.05
    right = seen.position[..., 0] > 0.05
    c = 2 * np.array([0.85, 0.5, 0.85]) - 1
    np.testing.assert_allclose(seen.normal[left], np.tile(c / np.linalg.norm(c), (left.sum(), 1)),
                               atol=1e-6)
    np.testing.assert_allclose(seen.normal[right], np.tile([0, 0, 1.0], (right.sum(), 1)), atol=1e-9)
    np.testing.assert_allclose(seen.face_normal[left], np.tile([0, 0, 1.0], (left.sum(), 1)))

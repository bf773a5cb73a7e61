"""Cycles' ray visibility and holdouts in the numpy ray casters (issue 18 point 1): each kind of
ray passes through the objects it does not see, in the grid caster (``raycast``) and the BVH
(``bvh.traverse``) alike; camera rays see nothing at a holdout; the packed material code keeps
the material index and carries the hidden bits."""
import numpy as np
from snapshots import mesh, snapshot, translation

from voxgi.voxgi_addon.scene import bvh as bvh_module
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded, primary_visibility
from voxgi.voxgi_addon.scene.snapshot import (
    RAY_ALL,
    RAY_CAMERA,
    RAY_DIFFUSE,
    RAY_GLOSSY,
    RAY_SHADOW,
    CameraData,
    MaterialData,
    ObjectData,
)

QUAD = ([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2), (0, 2, 3)])


def layered(front_visibility=RAY_ALL, front_holdout=False, holdout_materials=()):
    """Two quads facing +z: 'front' at z = 1 (material 1), 'back' at z = 0 (material 0)."""
    materials = [MaterialData("back", np.array([0.5, 0.5, 0.5], np.float32)),
                 MaterialData("front", np.array([0.8, 0.1, 0.1], np.float32))]
    meshes = [mesh("back", *QUAD, material=0), mesh("front", *QUAD, material=1)]
    objects = [ObjectData("back", "back", translation()),
               ObjectData("front", "front", translation(z=1.0), visibility=front_visibility,
                          holdout=front_holdout)]
    snap = snapshot(meshes, objects, materials)
    if holdout_materials:
        snap = type(snap)(**{**snap.__dict__, "holdout_materials": tuple(holdout_materials)})
    return snap


def down_rays(n=5):
    xy = np.linspace(-0.6, 0.6, n)
    origins = np.array([(x, y, 3.0) for x in xy for y in xy])
    return origins, np.tile([0.0, 0.0, -1.0], (len(origins), 1))


def test_each_kind_of_ray_passes_what_it_does_not_see():
    origins, dirs = down_rays()
    for hidden in (RAY_DIFFUSE, RAY_GLOSSY, RAY_SHADOW):
        tris = world_triangles(layered(RAY_ALL & ~hidden))
        assert tris.visibility is not None
        for ray in (RAY_DIFFUSE, RAY_GLOSSY, RAY_CAMERA):
            t, _, _, _ = closest_hits(tris, origins, dirs, ray=ray)
            expected = 3.0 if ray == hidden else 2.0  # through to the back quad, or the front
            np.testing.assert_allclose(t, expected)
            bt, btri, _, _ = bvh_module.closest_hits(tris, origins, dirs, ray=ray)
            np.testing.assert_allclose(bt, expected)
        # shadow rays from just above the back quad up to z = 2.5: blocked by the front quad
        # unless it casts no shadow
        start = origins.copy()
        start[:, 2] = 0.01
        blocked = occluded(tris, start, -dirs, 2.49)
        assert blocked.all() != (hidden == RAY_SHADOW)
        assert (bvh_module.occluded(tris, start, -dirs, 2.49) == blocked).all()


def test_everything_visible_keeps_no_mask():
    tris = world_triangles(layered())
    assert tris.visibility is None and tris.holdout is None
    assert tris.accepted(RAY_SHADOW) is None
    np.testing.assert_array_equal(bvh_module.material_code(tris), tris.materials)


def test_material_code_carries_the_hidden_bits():
    tris = world_triangles(layered(RAY_CAMERA | RAY_DIFFUSE))
    code = bvh_module.material_code(tris)
    # the code of bvh_common.glsl: code + 1 = material + 1 + 65536 · hidden
    plus = code + 1
    np.testing.assert_array_equal((plus & 0xFFFF) - 1, tris.materials)
    hidden = plus >> 16
    np.testing.assert_array_equal(hidden[tris.objects == 0], 0)
    np.testing.assert_array_equal(hidden[tris.objects == 1], RAY_GLOSSY | RAY_SHADOW)
    assert code.max() < 2 ** 24  # exact in the float32 texel


def camera_over_quads():
    """An orthographic camera at z = 4 looking down at the middle 1.6 m of the quads."""
    projection = np.diag([2 / 1.6, 2 / 1.6, -0.2, 1.0])
    return CameraData("o", translation(0, 0, 4), projection, (8, 8), "ORTHO", ortho_scale=1.6,
                      clip_start=0.1, clip_end=10.0)


def test_camera_rays_see_through_what_cameras_do_not_see():
    seen = primary_visibility(world_triangles(layered(RAY_ALL & ~RAY_CAMERA)), camera_over_quads())
    assert seen.hit.all() and (seen.object == 0).all()
    seen = primary_visibility(world_triangles(layered()), camera_over_quads())
    assert (seen.object == 1).all()


def test_a_holdout_hides_what_is_behind_and_shows_nothing():
    for snap in (layered(front_holdout=True), layered(holdout_materials=(1,))):
        tris = world_triangles(snap)
        assert tris.holdout is not None and tris.holdout[tris.objects == 1].all()
        seen = primary_visibility(tris, camera_over_quads())
        assert not seen.hit.any() and (seen.triangle == -1).all()
        # other rays meet it as any surface
        origins, dirs = down_rays()
        t, _, _, _ = closest_hits(tris, origins, dirs)
        np.testing.assert_allclose(t, 2.0)

"""The BVH built once per instanced mesh (voxgi_addon/scene/bvh.py ``build_scene_bvh``, issue 18
point 3): every triangle is in it once, every box holds what is under it, and rays meet exactly
what the grid caster and brute force meet, whatever the placements' rotations, scales and
shears; a scene without instancing gets the plain SAH build."""
import numpy as np
from meshes import box, uv_sphere

from voxgi.voxgi_addon.scene import bvh as bvh_module
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded
from voxgi.voxgi_addon.scene.snapshot import MaterialData, MeshData, ObjectData, SceneSnapshot


def _mesh(name, positions, triangles):
    return MeshData(name, np.asarray(positions, np.float32), np.asarray(triangles, np.int32),
                    np.zeros(len(triangles), np.int32))


def placed_scene(count=30, seed=1):
    """Spheres and boxes placed ``count`` times with random linear maps (rotation, scale,
    shear) and offsets, mixed with one-off meshes between them in the objects' order."""
    rng = np.random.default_rng(seed)
    meshes = [_mesh("sphere", *uv_sphere(10, 20)), _mesh("box", *box((1.0, 2.0, 0.5)))]
    objects = []
    for k in range(count):
        m = np.eye(4)
        m[:3, :3] = rng.normal(size=(3, 3)) * 0.7 + np.eye(3)
        m[:3, 3] = rng.uniform(-8, 8, 3)
        objects.append(ObjectData(f"o{k}", ("sphere", "box")[k % 2], m))
        if k % 7 == 3:
            lone = _mesh(f"lone{k}", *box(tuple(rng.uniform(0.5, 3.0, 3)), tuple(rng.uniform(-8, 8, 3))))
            meshes.append(lone)
            objects.append(ObjectData(lone.name, lone.name, np.eye(4)))
    return SceneSnapshot(meshes={m.name: m for m in meshes},
                         materials=[MaterialData("grey", np.full(3, 0.5, np.float32))],
                         objects=objects)


def rays(n=6000, seed=2):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return rng.uniform(-10, 10, (n, 3)), d / np.linalg.norm(d, axis=1, keepdims=True)


def test_instances_are_grouped_by_mesh():
    tris = world_triangles(placed_scene())
    groups, rest = bvh_module.instance_groups(tris)
    sizes = sorted((len(starts), size) for starts, size in groups)
    assert sizes == [(15, 12), (15, len(uv_sphere(10, 20)[1]))]
    assert len(rest) == 12 * 4  # the one-off boxes
    covered = np.concatenate([rest] + [(s[:, None] + np.arange(n)).ravel() for s, n in groups])
    np.testing.assert_array_equal(np.sort(covered), np.arange(len(tris)))


def test_instanced_build_holds_every_triangle_in_boxes_that_hold_them():
    tris = world_triangles(placed_scene())
    bvh = bvh_module.build_scene_bvh(tris)
    np.testing.assert_array_equal(np.sort(bvh.order), np.arange(len(tris)))
    corners = np.asarray(tris.positions)
    for node in np.flatnonzero(bvh.count > 0):
        inside = corners[bvh.order[bvh.first[node]:bvh.first[node] + bvh.count[node]]]
        assert (inside >= bvh.lo[node] - 1e-9).all() and (inside <= bvh.hi[node] + 1e-9).all()
    for node in np.flatnonzero(bvh.count == 0):
        for child in (node + 1, bvh.miss[node + 1]):
            assert (bvh.lo[child] >= bvh.lo[node]).all() and (bvh.hi[child] <= bvh.hi[node]).all()
    assert bvh.miss[0] == -1 and bvh.count.max() <= bvh_module.MAX_LEAF


def test_instanced_build_meets_what_the_grid_caster_meets():
    tris = world_triangles(placed_scene())
    bvh = bvh_module.build_scene_bvh(tris)
    origins, dirs = rays()
    t, tri, u, v = bvh_module.traverse(bvh, tris, origins, dirs)
    gt, gtri, gu, gv = closest_hits(tris, origins, dirs)
    assert (gtri >= 0).mean() > 0.1  # 800 of the rays meet something
    np.testing.assert_array_equal(tri, gtri)
    np.testing.assert_allclose(t[tri >= 0], gt[gtri >= 0], rtol=1e-9)
    blocked = np.isfinite(bvh_module.traverse(bvh, tris, origins, dirs, 1e-4, 2.0 - 1e-4,
                                              any_hit=True)[0])
    np.testing.assert_array_equal(blocked, occluded(tris, origins, dirs, 2.0))


def test_a_scene_without_instancing_gets_the_sah_build():
    snapshot = placed_scene(count=1)
    tris = world_triangles(snapshot)
    assert bvh_module.instance_groups(tris) is None
    plain, scene = bvh_module.build_bvh(tris), bvh_module.build_scene_bvh(tris)
    for field in ("lo", "hi", "miss", "first", "count", "order"):
        np.testing.assert_array_equal(getattr(plain, field), getattr(scene, field))


def test_placements_are_transformed_as_each_object_alone():
    """world_triangles transforms the objects that place one mesh together: corners and shading
    normals equal those of each object transformed on its own (geometry.object_vertices_world,
    skinning.transform_normals), in the objects' order."""
    from voxgi.voxgi_addon.scene.skinning import transform_normals

    snapshot = placed_scene()
    sphere = snapshot.meshes["sphere"]
    rng = np.random.default_rng(5)
    normals = rng.normal(size=(len(sphere.triangles), 3, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    meshes = {**snapshot.meshes, "sphere": MeshData(sphere.name, sphere.positions, sphere.triangles,
                                                    sphere.triangle_materials,
                                                    corner_normals=normals.astype(np.float32))}
    snapshot = SceneSnapshot(meshes=meshes, materials=snapshot.materials, objects=snapshot.objects)
    tris = world_triangles(snapshot)
    corners, shading = [], []
    for obj in snapshot.objects:
        mesh = snapshot.meshes[obj.mesh]
        m = np.asarray(obj.world_matrix)
        p = np.asarray(mesh.positions, np.float64) @ m[:3, :3].T + m[:3, 3]
        # a mirroring placement turns the winding: the second and third corners swap
        order = [0, 2, 1] if np.linalg.det(m[:3, :3]) < 0.0 else [0, 1, 2]
        corners.append(p[np.asarray(mesh.triangles)][:, order])
        if mesh.corner_normals is None:  # flat: the face normal at every corner
            c = corners[-1]
            n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
            shading.append(np.repeat((n / np.linalg.norm(n, axis=1, keepdims=True))[:, None], 3, 1))
        else:
            shading.append(transform_normals(m, np.asarray(mesh.corner_normals, np.float64)
                                             .reshape(-1, 3)).reshape(-1, 3, 3)[:, order])
    np.testing.assert_allclose(tris.positions, np.concatenate(corners), atol=1e-12)
    np.testing.assert_allclose(tris.corner_normals, np.concatenate(shading), atol=1e-9)


def test_leaf_codes_past_a_million_triangles_survive_packing():
    """Leaf codes are stored as float bits: a leaf whose first triangle is past 2²⁰ (where
    first · 16 is no longer an exact float value) packs and reads back exactly."""
    firsts = np.array([-1, 0, (1 << 20) + 1, (1 << 23) - 5], np.int32)
    counts = np.array([0, 8, 3, 5], np.int32)
    fake = bvh_module.BVH(lo=np.zeros((4, 3)), hi=np.ones((4, 3)), miss=np.array([-1, 2, 3, -1], np.int32),
                          first=firsts, count=counts, order=np.zeros(0, np.int32), depth=2)
    tris = world_triangles(placed_scene(count=0))
    packed = bvh_module.pack_bvh(fake, tris, layouts=1)
    codes = bvh_module.leaf_codes(packed.nodes.reshape(-1, 4)[1:8:2, 3])
    np.testing.assert_array_equal(codes, [-1, 8, ((1 << 20) + 1) * 16 + 3, ((1 << 23) - 5) * 16 + 5])
    values = packed.nodes.reshape(-1, 4)[3:8:2, 3]
    assert np.isfinite(values).all() and (values > 0).all() and (values >= np.finfo(np.float32).tiny).all()


def test_objects_that_share_a_mesh_keep_their_own_materials():
    """``ObjectData.materials`` (a Base Color by Object Info › Random, one variant per object):
    each placement's triangles carry its own material, the others their mesh's, and a ray that
    meets a placement in the instanced BVH reads that placement's."""
    from dataclasses import replace

    scene = placed_scene(count=8)
    scene = replace(scene, materials=[*scene.materials, *(MaterialData(f"variant {k}", np.full(
        3, 0.1 * k, np.float32)) for k in range(1, 4))])
    objects = [replace(o, materials=((0, 1 + k % 3),)) if o.mesh == "sphere" else o
               for k, o in enumerate(scene.objects)]
    tris = world_triangles(replace(scene, objects=objects))
    for index, obj in enumerate(objects):
        own = np.asarray(tris.materials)[np.asarray(tris.objects) == index]
        assert len(own) and (own == (obj.materials[0][1] if obj.materials else 0)).all()
    bvh = bvh_module.build_scene_bvh(tris)
    origins, directions = rays()
    _, triangle, _, _ = bvh_module.traverse(bvh, tris, origins, directions)
    met = triangle[triangle >= 0]
    assert len(met) > 100
    expected = [objects[i].materials[0][1] if objects[i].materials else 0
                for i in np.asarray(tris.objects)[met]]
    np.testing.assert_array_equal(np.asarray(tris.materials)[met], expected)

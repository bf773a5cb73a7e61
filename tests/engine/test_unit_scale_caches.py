"""Issue 22 (1): voxel caches of the right size whatever the unit scale.

A skinned mesh whose object matrix carries a unit scale (an armature at 0.01 over a mesh and
bones in centimetres, as Blender's glTF/FBX importers leave Mixamo-style rigs) must give the
caches and cascades of the same character built at scale 1: its cache is voxelized in model
space at span / scale and the skinning matrices carry it to the world span.
"""
import numpy as np
import pytest
from meshes import box, uv_sphere
from snapshots import ObjectData, SkinData, mesh, snapshot, translation
from test_cascades import bent_tube_rig, rotation

from voxgi.voxgi_addon.gi.cascades import build_cascades, place_cascades
from voxgi.voxgi_addon.gi.update import GISettings, update_gi
from voxgi.voxgi_addon.scene.skinning import skin_points
from voxgi.voxgi_addon.scene.snapshot import ArmatureData, SceneSnapshot
from voxgi.voxgi_addon.voxelize import object_scale
from voxgi.voxgi_addon.voxelize.incremental import CacheStore, refresh_caches
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches
from voxgi.voxgi_addon.voxelize.surface import voxelize_triangles

SPAN = 0.05
CASCADES = 3


def _scaled(matrix, unit):
    """A bone/object matrix of a rig built in units of ``unit`` metres: translation / unit."""
    m = np.array(matrix, np.float64)
    m[..., :3, 3] /= unit
    return m


def rig_scene(unit=1.0, bend=35.0, object_stretch=None, extra_objects=()):
    """The bent tube rig of test_cascades at ``unit`` metres per model unit: vertices and bones
    in model units, the armature object scaled by ``unit`` and the mesh parented to it (its
    world matrix is the armature's), as the importers leave it. ``object_stretch`` (3,) scales
    the mesh object further (non-uniform scale of the skinned object itself)."""
    pos, tris, rig, skin = bent_tube_rig(bend)
    arm_world = rig.world_matrix @ np.diag([unit, unit, unit, 1.0])
    scaled_rig = ArmatureData(rig.name, rig.bone_names, rig.parents,
                              _scaled(rig.rest_matrices, unit), _scaled(rig.pose_matrices, unit),
                              arm_world)
    obj_world = arm_world if object_stretch is None else arm_world @ np.diag([*object_stretch, 1])
    snap = snapshot([mesh("Tube", pos / unit, tris, skin=skin), *[m for m, _ in extra_objects]],
                    [ObjectData("Tube", "Tube", obj_world, "skinned", "Rig"),
                     *[o for _, o in extra_objects]])
    return SceneSnapshot(meshes=snap.meshes, materials=snap.materials, objects=snap.objects,
                         armatures={"Rig": scaled_rig})


def _keys(cells):
    c = np.asarray(cells, np.int64)
    return (c[:, 0] * 4096 + c[:, 1]) * 4096 + c[:, 2]


def _iou(a, b):
    ka, kb = np.unique(_keys(a)), np.unique(_keys(b))
    inter = len(np.intersect1d(ka, kb))
    return inter / max(len(ka) + len(kb) - inter, 1) if len(ka) + len(kb) else 1.0


def _cascades(snap, caches, centre=(0.3, -0.2, 0.0)):
    grids = place_cascades(np.asarray(centre), SPAN, 32, len(caches.cascade_stats))
    return build_cascades(caches, snap, grids)


def test_the_scaled_rig_is_the_same_character_in_the_world():
    one, cm = rig_scene(1.0), rig_scene(0.01)
    a = skin_points(one.armatures["Rig"], one.objects[0].world_matrix,
                    one.meshes["Tube"].positions, *_skin(one))
    b = skin_points(cm.armatures["Rig"], cm.objects[0].world_matrix,
                    cm.meshes["Tube"].positions, *_skin(cm))
    np.testing.assert_allclose(a, b, atol=1e-5)
    assert np.ptp(cm.meshes["Tube"].positions, axis=0).max() > 100  # centimetres


def _skin(snap):
    skin = snap.meshes["Tube"].skin
    return skin.weights, skin.bone_indices


@pytest.mark.parametrize("unit", [0.01, 0.0254, 0.001])
def test_a_unit_scaled_skinned_mesh_gets_the_caches_and_cascades_of_the_unscaled_one(unit):
    one, scaled = rig_scene(1.0), rig_scene(unit)
    ref, got = build_scene_caches(one, SPAN, CASCADES), build_scene_caches(scaled, SPAN, CASCADES)
    key = got.bindings["Tube"].cache_key
    assert key == f"Tube|span:{unit!r}"
    assert not got.skipped and not any("scale" in w for w in got.warnings)
    for cascade, (r, g) in enumerate(zip(ref.caches["Tube"], got.caches[key])):
        assert g.span == pytest.approx(SPAN * 2**cascade / unit, rel=1e-12)  # model-space span
        # the same lattice up to the unit: the same voxels, give or take rounding at cell faces
        assert abs(g.voxel_count - r.voxel_count) <= 0.01 * r.voxel_count
        assert _iou(g.cells(), r.cells()) >= 0.98
    assert [s.voxel_count for s in got.cascade_stats] == pytest.approx(
        [s.voxel_count for s in ref.cascade_stats], rel=0.01)
    refs, gots = _cascades(one, ref), _cascades(scaled, got)
    assert refs[0].voxel_count > 500  # the tube is in cascade 0; the coarser ones hold its rim
    for r, g in zip(refs, gots):
        assert abs(g.voxel_count - r.voxel_count) <= max(2, 0.02 * r.voxel_count)
        assert _iou(g.cells, r.cells) >= (0.97 if r.voxel_count > 500 else 0.7)
        # normals are carried by the scaled skinning matrices and renormalised
        assert (np.linalg.norm(g.normal, axis=1) > 0.99).all()


def test_the_model_space_span_keeps_a_centimetre_rig_inside_the_cache_limits():
    """Before: the cm mesh was voxelized at metre spans, 100× too many cells per axis — the
    finest cascade was skipped (over 1024 cells) and the others held ~10⁴× the voxels."""
    scaled = rig_scene(0.01)
    got = build_scene_caches(scaled, 0.01, 2)
    assert not got.skipped
    ref = build_scene_caches(rig_scene(1.0), 0.01, 2)
    assert got.total_voxels == pytest.approx(ref.total_voxels, rel=0.01)


def test_a_non_uniformly_scaled_skinned_mesh_bakes_the_residual_and_keeps_world_span_voxels():
    stretch = np.array([2.0, 1.0, 0.5])
    scaled = rig_scene(0.01, object_stretch=stretch)
    got = build_scene_caches(scaled, SPAN, CASCADES)
    key = got.bindings["Tube"].cache_key
    s, residual = object_scale.parse_skin_key(key)
    assert s == pytest.approx(0.01, rel=1e-12)  # |det diag(2, 1, 0.5)| = 1
    np.testing.assert_allclose(residual, np.diag(stretch), atol=1e-12)
    assert any("non-uniform" in w and "'Tube'" in w for w in got.warnings)
    # the same tube with the stretch applied to its rest vertices, unit 1: the same voxels
    pos, tris, rig, skin = bent_tube_rig(35.0)
    applied = rig_scene(1.0)
    applied = SceneSnapshot(
        meshes={"Tube": mesh("Tube", pos * stretch, tris, skin=skin)}, materials=applied.materials,
        objects=applied.objects, armatures=applied.armatures)
    ref = build_scene_caches(applied, SPAN, CASCADES)
    for r, g in zip(ref.caches["Tube"], got.caches[key]):
        assert abs(g.voxel_count - r.voxel_count) <= 0.01 * r.voxel_count
    # in the world the residual is undone by the bones: the cascades follow the skinned mesh
    posed = skin_points(scaled.armatures["Rig"], scaled.objects[0].world_matrix,
                        scaled.meshes["Tube"].positions, *_skin(scaled))
    grids = place_cascades(posed.mean(axis=0), SPAN, 64, 1)
    cells = build_cascades(got, scaled, grids)[0].cells
    again = voxelize_triangles(posed - grids[0].origin, scaled.meshes["Tube"].triangles, SPAN)
    assert 0.9 <= len(cells) / len(again.cells) <= 1.1
    assert _iou(cells, again.cells) >= 0.75  # as the unscaled skinned tube (test_cascades)


def test_skin_keys_round_trip_exactly():
    for s, residual in ((1.0, np.eye(3)), (0.01, np.eye(3)), (1 / 3, np.diag([1.1, 1 / 1.1, 1.0]))):
        key = object_scale.skin_key("Body|span:x", s, residual)  # names may hold the separator
        back_s, back_residual = object_scale.parse_skin_key(key, "Body|span:x")
        assert back_s == s and np.array_equal(back_residual, residual)
    assert object_scale.skin_key("Body", 1.0 + 1e-9, np.eye(3)) == "Body"
    for degrees in (0, 17, 30, 61):  # the key must not change as the rig turns
        m = rotation((0, 0, 1), degrees) @ rotation((1, 0, 0), 90) @ np.diag([0.0254] * 3 + [1])
        assert object_scale.skin_bake(m) == (0.0254, pytest.approx(np.eye(3), abs=0))


def test_posing_or_moving_a_scaled_rig_reuses_its_caches_and_a_rescale_is_reported():
    store = CacheStore()
    first = refresh_caches(store, rig_scene(0.01, bend=10.0), SPAN, CASCADES)
    assert first.voxelized == ["Tube|span:0.01"]
    posed = rig_scene(0.01, bend=50.0)
    again = refresh_caches(store, posed, SPAN, CASCADES)
    assert again.voxelized == [] and again.reused == ["Tube|span:0.01"]
    # the armature rescaled after voxelizing: the old caches, resized by the skinning, say so
    bigger = rig_scene(0.02, bend=50.0)
    bigger = SceneSnapshot(meshes=posed.meshes, materials=posed.materials,
                           objects=bigger.objects, armatures=bigger.armatures)
    warnings = []
    grids = place_cascades(np.zeros(3), SPAN, 64, CASCADES)
    out = build_cascades(first.caches, bigger, grids, warnings)
    assert any("'Tube' changed scale" in w for w in warnings)
    assert out[0].voxel_count > 1.5 * build_cascades(first.caches, posed, grids)[0].voxel_count


def test_rigid_meshes_under_scaled_parents_keep_their_baked_scale():
    """A rigid mesh in centimetres whose world matrix carries 0.01 (a parent chain of scaled
    empties: the snapshot holds the composed matrix) gets the voxels of the metre mesh."""
    pos, tris = uv_sphere(rings=12, segments=24, radius=0.4)
    parent = translation(0.5, 0.2, 0.1) @ rotation((0, 0, 1), 30) @ np.diag([0.1, 0.1, 0.1, 1])
    child = rotation((1, 0, 0), 15) @ np.diag([0.1, 0.1, 0.1, 1])
    cm = snapshot([mesh("S", pos * 100, tris)], [ObjectData("S", "S", parent @ child, "rigid")])
    m = snapshot([mesh("S", pos, tris)],
                 [ObjectData("S", "S", translation(0.5, 0.2, 0.1) @ rotation((0, 0, 1), 30)
                             @ rotation((1, 0, 0), 15), "rigid")])
    a, b = build_scene_caches(cm, SPAN, 2), build_scene_caches(m, SPAN, 2)
    assert a.bindings["S"].cache_key.startswith("S|scale:")
    x, y = _cascades(cm, a, (0.5, 0.2, 0.1)), _cascades(m, b, (0.5, 0.2, 0.1))
    assert x[0].voxel_count > 200 and _iou(x[0].cells, y[0].cells) >= 0.98
    assert [c.voxel_count for c in x] == pytest.approx([c.voxel_count for c in y], abs=2)


def test_an_unchanged_update_reuses_the_state_and_a_move_redoes_only_what_moved():
    pos, tris = box((4.0, 4.0, 0.1), centre=(0.0, 0.0, -0.7))
    floor = (mesh("Floor", pos, tris), ObjectData("Floor", "Floor", np.eye(4)))
    snap = rig_scene(0.01, bend=20.0, extra_objects=[floor])
    caches = build_scene_caches(snap, SPAN, 2)
    settings = GISettings(resolution=32)
    first = update_gi(snap, caches, settings, anchor=np.zeros(3))
    same = update_gi(snap, caches, settings, anchor=np.zeros(3), previous=first)
    assert same.reused == "all" and same.cascades is first.cascades
    assert same.radiance is first.radiance and same.octree is first.octree
    # an equal but newly taken snapshot (new arrays) is recognised too
    again = rig_scene(0.01, bend=20.0, extra_objects=[floor])
    assert update_gi(again, caches, settings, anchor=np.zeros(3), previous=first).reused == "all"
    # pose the character: its voxels are placed again, the floor's are taken as they were
    posed = rig_scene(0.01, bend=45.0, extra_objects=[floor])
    moved = update_gi(posed, caches, settings, anchor=np.zeros(3), previous=first)
    assert moved.reused == "objects" and moved.placed_objects == ("Tube",)
    fresh = update_gi(posed, caches, settings, anchor=np.zeros(3))
    for x, y in zip(moved.cascades, fresh.cascades):
        np.testing.assert_array_equal(x.cells, y.cells)
        np.testing.assert_allclose(x.albedo, y.albedo)
        np.testing.assert_allclose(x.normal, y.normal, atol=1e-6)
    for x, y in zip(moved.radiance, fresh.radiance):
        np.testing.assert_allclose(x, y, atol=1e-6)
    # other caches (re-voxelized) or settings: nothing is reused
    other = build_scene_caches(posed, SPAN, 2)
    assert update_gi(posed, other, settings, anchor=np.zeros(3), previous=moved).reused == ""
    assert update_gi(posed, caches, GISettings(resolution=32, light_samples=2),
                     anchor=np.zeros(3), previous=moved).reused == "objects"


def test_skin_data_is_unchanged_by_the_bake():
    """The weights a cache voxel carries are the mesh's: the scale touches positions only."""
    scaled = rig_scene(0.01)
    cache = build_scene_caches(scaled, SPAN, 1).caches["Tube|span:0.01"][0]
    attrs = cache.attributes()
    assert attrs.weights is not None and np.allclose(attrs.weights.sum(axis=1), 1.0, atol=0.02)
    assert isinstance(scaled.meshes["Tube"].skin, SkinData)

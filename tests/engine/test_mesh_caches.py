"""The scene voxelization job: counts, reports and bad input."""
import numpy as np
import pytest
from meshes import box, tube, uv_sphere
from snapshots import MaterialData, ObjectData, SkinData, mesh, snapshot, translation

from voxgi.voxgi_addon.errors import VoxGICancelled, VoxGIError
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches
from voxgi.voxgi_addon.voxelize.surface import voxelize_triangles


def test_counts_per_cascade_match_the_voxelizer_and_flags_mark_finer_cascades():
    pos, tris = uv_sphere(rings=10, segments=20)
    snap = snapshot([mesh("Sphere", pos, tris)], [("Sphere", "Sphere", translation())])
    result = build_scene_caches(snap, base_span=0.1, cascade_count=3)
    for cascade, stats in enumerate(result.cascade_stats):
        span = 0.1 * 2**cascade
        expected = voxelize_triangles(pos.astype(np.float32), tris, span).voxel_count
        assert stats.span == pytest.approx(span)
        assert stats.voxel_count == expected
        assert stats.nbytes == expected * 12  # position + normal + colour words
        cache = result.caches["Sphere"][cascade]
        assert set(cache.finer_flags().tolist()) == {0 if cascade == 0 else 1}
    assert result.total_voxels == sum(s.voxel_count for s in result.cascade_stats)


def test_cache_centres_normals_and_colours_describe_the_surface():
    pos, tris = uv_sphere(rings=16, segments=32, radius=1.0)
    red = MaterialData("red", np.array([0.8, 0.1, 0.1], np.float32), roughness=0.25)
    snap = snapshot([mesh("S", pos, tris)], [("S", "S", translation())], materials=[red])
    cache = build_scene_caches(snap, 0.1, 1).caches["S"][0]
    centres = cache.centres()
    radius = np.linalg.norm(centres, axis=1)
    sag = 1 - np.cos(np.pi / 16)  # how far the faceted sphere dips inside the round one
    assert np.abs(radius - 1.0).max() <= 0.1 * np.sqrt(3) / 2 + sag  # within half a voxel diagonal
    attrs = cache.attributes()
    outward = centres / radius[:, None]
    assert np.median((attrs.normal * outward).sum(axis=1)) > 0.98
    assert np.abs(attrs.albedo - [0.8, 0.1, 0.1]).max() <= 1 / 255
    assert np.abs(attrs.specular - 0.75).max() <= 1 / 255


def test_linked_duplicates_share_one_cache():
    pos, tris = box()
    snap = snapshot([mesh("Cube", pos, tris)],
                    [("A", "Cube", translation(0, 0, 0)), ("B", "Cube", translation(5, 0, 0))])
    result = build_scene_caches(snap, 0.25, 2)
    assert list(result.caches) == ["Cube"]
    assert result.bindings["A"].cache_key == result.bindings["B"].cache_key == "Cube"
    assert np.allclose(result.bindings["B"].rigid_matrix[:3, 3], [5, 0, 0])


def test_non_uniform_scale_is_baked_and_warned():
    pos, tris = uv_sphere(rings=8, segments=16)
    snap = snapshot([mesh("S", pos, tris)], [("Squashed", "S", translation(1, 2, 3, scale=(2, 1, 0.5)))])
    result = build_scene_caches(snap, 0.1, 1)
    assert any("'Squashed' has non-uniform scale" in w and "baked" in w for w in result.warnings)
    binding = result.bindings["Squashed"]
    assert np.allclose(binding.rigid_matrix, translation(1, 2, 3))
    baked = (pos.astype(np.float32) * [2, 1, 0.5])
    expected = voxelize_triangles(baked, tris, 0.1).voxel_count
    assert result.caches[binding.cache_key][0].voxel_count == expected


def test_uniform_scale_is_baked_silently():
    pos, tris = box()
    snap = snapshot([mesh("Cube", pos, tris)], [("Big", "Cube", translation(scale=(2, 2, 2)))])
    result = build_scene_caches(snap, 0.25, 1)
    assert not result.warnings
    cache = result.caches[result.bindings["Big"].cache_key][0]
    assert cache.voxel_count == 9 * 9 * 9 - 7 * 7 * 7  # the 2 m cube at span 0.25


def test_mesh_too_big_for_1024_cells_is_skipped_at_that_span_only():
    pos, tris = box(size=(120.0, 1.0, 1.0))
    snap = snapshot([mesh("Long", pos, tris)], [("Long", "Long", translation())])
    result = build_scene_caches(snap, 0.1, 2)
    assert result.caches["Long"][0] is None and result.caches["Long"][1] is not None
    (skip,) = result.skipped
    assert (skip.mesh, skip.cascade, skip.span) == ("Long", 0, 0.1)
    assert "mesh 'Long' skipped at cascade 0 (span 0.1 m): needs 1201×11×11 voxels" in str(skip)
    assert result.caches["Long"][1].finer_flags().max() == 0  # no finer cascade holds it


def test_degenerate_and_nan_triangles_are_dropped_and_counted():
    pos, tris = box()
    pos = np.vstack([pos, [[0, 0, 0], [1, 1, 1], [2, 2, 2], [np.nan, 0, 0]]])
    extra = [[8, 9, 10], [8, 8, 9], [0, 1, 11]]  # collinear, repeated vertex, NaN vertex
    snap = snapshot([mesh("M", pos, np.vstack([tris, extra]))], [("M", "M", translation())])
    result = build_scene_caches(snap, 0.25, 1)
    assert result.dropped_triangles == {"M": 3}
    assert "mesh 'M': dropped 3 triangles (2 zero-area, 1 with NaN/inf vertices)" in result.warnings
    assert result.caches["M"][0].voxel_count == build_scene_caches(
        snapshot([mesh("M", box()[0], tris)], [("M", "M", translation())]), 0.25, 1
    ).caches["M"][0].voxel_count


def test_mesh_with_no_usable_faces_gets_no_voxels_and_a_warning():
    snap = snapshot([mesh("Flat", np.zeros((3, 3)), [[0, 1, 2]])], [("Flat", "Flat", translation())])
    result = build_scene_caches(snap, 0.1, 2)
    assert result.caches["Flat"] == [None, None]
    assert "mesh 'Flat' has no usable faces; it gets no voxels" in result.warnings


def test_empty_scene_and_bad_settings_raise_clear_errors():
    with pytest.raises(VoxGIError, match="no visible mesh objects"):
        build_scene_caches(snapshot([], []), 0.1, 3)
    pos, tris = box()
    snap = snapshot([mesh("Cube", pos, tris)], [("Cube", "Cube", translation())])
    with pytest.raises(VoxGIError, match="positive number of metres"):
        build_scene_caches(snap, 0.0, 3)
    with pytest.raises(VoxGIError, match="between 1 and 8"):
        build_scene_caches(snap, 0.1, 0)


def test_cancel_stops_the_job():
    pos, tris = box()
    snap = snapshot([mesh("Cube", pos, tris)], [("Cube", "Cube", translation())])
    with pytest.raises(VoxGICancelled):
        build_scene_caches(snap, 0.1, 3, cancel=lambda: True)


def test_object_with_nan_matrix_is_skipped_with_a_warning():
    pos, tris = box()
    bad = translation()
    bad[0, 0] = np.nan
    snap = snapshot([mesh("Cube", pos, tris)], [("Bad", "Cube", bad), ("Good", "Cube", translation())])
    result = build_scene_caches(snap, 0.25, 1)
    assert "object 'Bad': its matrix has NaN/inf values; skipped" in result.warnings
    assert "Bad" not in result.bindings and "Good" in result.bindings


def test_skinned_voxels_carry_the_weights_of_the_nearest_vertex():
    """A known rig: a tube along Z with 3 bones; vertex weights vary ring by ring."""
    pos, tris = tube(rings=9, segments=12, length=3.0, radius=0.3)
    ring = np.repeat(np.arange(9), 12)
    weights = np.zeros((len(pos), 4), np.float32)
    weights[:, 0] = np.clip(1 - ring / 4, 0, 1)
    weights[:, 1] = 1 - np.abs(ring - 4) / 4
    weights[:, 2] = np.clip((ring - 4) / 4, 0, 1)
    weights /= weights.sum(axis=1, keepdims=True)
    indices = np.tile(np.array([0, 1, 2, 0], np.uint8), (len(pos), 1))
    skin = SkinData(weights=weights, bone_indices=indices, armature="Rig")
    snap = snapshot([mesh("Tube", pos, tris, skin=skin)],
                    [ObjectData("Tube", "Tube", translation(), "skinned", "Rig")])
    cache = build_scene_caches(snap, 0.1, 1).caches["Tube"][0]
    assert cache.skinned and cache.nbytes == cache.voxel_count * 20
    centres = cache.centres()
    nearest = np.argmin(((centres[:, None, :] - pos[None].astype(np.float64)) ** 2).sum(-1), axis=1)
    attrs = cache.attributes()
    assert np.abs(attrs.weights - weights[nearest]).max() <= 1 / 255 + 1e-6
    assert (attrs.bone_indices == indices[nearest]).all()
    assert np.allclose(attrs.weights.sum(axis=1), 1.0)

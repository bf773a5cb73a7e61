"""The GPU probe bake (render/gpu_probes.py) against its numpy reference
(voxgi_addon/probes/octree_bake.py): same octree, same directions, within 1 %."""
import bpy
import numpy as np
import pytest
import scenes


@pytest.fixture
def cornell(voxgi):
    scene = bpy.context.scene
    scenes.build_test_cornell_box(scene)
    scene.voxgi.base_span = 0.07
    scene.voxgi.grid_resolution = "64"
    return scene


def test_gpu_and_numpy_octree_bakes_agree_within_one_percent(cornell):
    from cycles_reference import snapshot_triangles

    from voxgi.blender.session import scene_session
    from voxgi.blender.settings import cone_settings
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_probes import gpu_probe_sh, octree_state
    from voxgi.render.gpu_volume import GPUVolume
    from voxgi.voxgi_addon.probes import sh
    from voxgi.voxgi_addon.probes.octree_bake import octree_probe_sh
    from voxgi.voxgi_addon.probes.placement import place_probes, scene_box

    ready, why = ensure_gpu_context()
    assert ready, f"no GPU context in background mode: {why}"
    snapshot, tris = snapshot_triangles(cornell)
    state = octree_state(bpy.context, cornell, snapshot)
    layout = place_probes(tris.positions, tris.normals, *scene_box(tris.positions), 3)
    inside = (np.abs(layout.positions[:, :2]) < 0.99).all(axis=1) & (layout.positions[:, 2] > 0.01) \
        & (layout.positions[:, 2] < 1.99)
    positions = layout.positions[inside]
    dirs = sh.sample_directions(64, seed=5)
    cones = cone_settings(cornell.voxgi)
    world = np.zeros(3)
    volume = GPUVolume()
    volume.update(state.octree, cones)
    gpu = gpu_probe_sh(volume, positions, dirs, world, cones)
    reference = octree_probe_sh(state.octree, positions, dirs, cones, world)
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    e_gpu = np.stack([sh.irradiance(c, axes) for c in gpu])
    e_ref = np.stack([sh.irradiance(c, axes) for c in reference])
    difference = np.abs(e_gpu - e_ref).sum() / np.abs(e_ref).sum()
    print(f"GPU vs numpy octree bake ({len(positions)} probes × 64 rays): irradiance relative L1 "
          f"{difference:.5f}; SH max |Δ| {np.abs(gpu - reference).max():.4f} of {np.abs(reference).max():.3f}")
    assert e_ref.mean() > 0.1
    assert difference < 0.01
    assert scene_session(cornell.name_full).gi_state is state


def test_bake_operator_on_the_gpu_keeps_a_grid_close_to_the_exact_bake(cornell):
    from voxgi.blender.probe_store import load_grids
    from voxgi.voxgi_addon.probes import sh

    cornell.voxgi.probe_resolution = 4
    cornell.voxgi.probe_directions = 128
    cornell.voxgi.probe_bake_method = "RAYS"
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    exact = load_grids(cornell)[0]
    cornell.voxgi.probe_bake_method = "VOXELS_GPU"
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    voxels = load_grids(cornell)[0]
    np.testing.assert_array_equal(voxels.positions, exact.positions)
    np.testing.assert_array_equal(voxels.volume_masks, exact.volume_masks)
    inside = np.flatnonzero(exact.enabled & (exact.flags == 0))
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    a = np.stack([sh.irradiance(np.asarray(exact.sh[i], float), axes) for i in inside])
    b = np.stack([sh.irradiance(np.asarray(voxels.sh[i], float), axes) for i in inside])
    difference = np.abs(a - b).sum() / np.abs(a).sum()
    print(f"octree (GPU) bake vs exact bake: irradiance relative L1 {difference:.3f}, mean ratio "
          f"{b.mean() / a.mean():.3f}")
    assert difference < 0.5  # the voxel one-bounce is an approximation; same scale and colours

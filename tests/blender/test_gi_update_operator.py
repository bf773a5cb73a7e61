"""voxgi.update: cascades, light and octree for the current frame, reusing the caches."""
import bpy
import numpy as np


def test_update_reuses_the_caches_when_objects_and_the_camera_move(voxgi, session):
    from voxgi.blender.demo_scene import build_demo_scene

    scene = bpy.context.scene
    build_demo_scene(scene)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    state = session.scene_session(scene.name_full)
    caches = state.caches
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    first = state.gi_state
    assert sum(first.voxel_counts) > 1000
    lines = [message for _, message in state.last_report]
    assert any(m.startswith("GI updated: cascade voxels") for m in lines)
    octree_line = next(m for m in lines if m.startswith("octree: "))
    assert f"L{first.octree.depth} sparse" in octree_line and "MB" in octree_line

    sphere = next(o for o in scene.objects if o.type == "MESH" and "Sphere" in o.name)
    sphere.location.z += 0.3
    scene.camera.location.x += 0.05  # less than a coarse voxel: the grids must not move
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    second = state.gi_state
    assert state.caches is caches  # nothing was re-voxelized
    for a, b in zip(first.grids, second.grids):
        assert np.array_equal(a.origin, b.origin)
    assert any(not np.array_equal(a.cells, b.cells) for a, b in zip(first.cascades, second.cascades))

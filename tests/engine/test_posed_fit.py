"""The view fit of a pose (docs/gi_pipeline.md "Posed updates"): the probe traces the skinned
objects apart from the others, whose hits it keeps from the previous probe, and gets the very
points of one trace of everything; a grid of fewer cells by bounding boxes hits at the same
distances."""
import dataclasses

import numpy as np
from meshes import box
from snapshots import ObjectData, SkinData, mesh
from view_scenes import room_scene

from voxgi.voxgi_addon.gi.view_fit import fit_view, probe_view
from voxgi.voxgi_addon.scene import raycast
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import ArmatureData


def posed_room(angle):
    """The 5 m room with a skinned column (two bones) in it, its upper bone turned by
    ``angle`` (radians) about x."""
    snap = room_scene(5.0, 2.0)
    positions, triangles = box((0.4, 0.4, 2.0), (0.3, 0.2, 1.0))
    upper = positions[:, 2] > 1.0
    weights = np.zeros((len(positions), 4), np.float32)
    weights[:, 0] = 1.0
    indices = np.zeros((len(positions), 4), np.uint8)
    indices[upper, 0] = 1
    column = mesh("Column", positions, triangles, skin=SkinData(weights, indices, "Rig"))
    rest = np.stack([np.eye(4), np.eye(4)])
    rest[1, :3, 3] = (0.3, 0.2, 1.0)
    turn = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    turn[1:3, 1:3] = ((c, -s), (s, c))
    pose = rest.copy()
    pose[1] = rest[1] @ turn
    rig = ArmatureData("Rig", ("Lower", "Upper"), np.array([-1, 0], np.int32), rest, pose,
                       np.eye(4))
    return dataclasses.replace(
        snap, meshes={**snap.meshes, "Column": column}, armatures={"Rig": rig},
        objects=[*snap.objects, ObjectData("Column", "Column", np.eye(4), "skinned", "Rig")])


def test_a_posed_probe_traces_the_skinned_objects_alone_and_sees_what_one_trace_sees():
    first = posed_room(0.0)
    probe = probe_view(first)
    assert probe.still is not None and probe.source == "camera"
    for angle in (0.3, -0.6, 1.1):
        posed = dataclasses.replace(first, armatures={"Rig": posed_room(angle).armatures["Rig"]})
        again = probe_view(posed, previous=probe)
        assert again.still is probe.still  # the room's hits kept, only the column traced
        whole = probe_view(posed, triangles=world_triangles(posed))
        assert np.array_equal(again.points, whole.points)
        assert not np.array_equal(again.points, probe.points)  # the column moved in view
        fitted = fit_view(posed, previous=fit_view(first))
        fresh = fit_view(posed, previous=fit_view(first), probe=whole)
        assert fitted.base_span == fresh.base_span
        assert np.array_equal(fitted.centre, fresh.centre)
    view = np.array(first.camera.world_matrix)
    view[0, 3] += 0.1
    moved = dataclasses.replace(first, camera=dataclasses.replace(first.camera, world_matrix=view))
    assert probe_view(moved, previous=probe).still is not probe.still  # a new view: traced


def test_a_grid_by_bounding_boxes_hits_what_the_exact_grid_hits():
    snap = posed_room(0.4)
    tris = world_triangles(snap)
    rng = np.random.default_rng(2)
    origins = rng.uniform(-3.0, 3.0, (4000, 3)) + [0.0, 0.0, 2.5]
    dirs = rng.normal(size=(4000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    exact = raycast.closest_hits(raycast.build_grid(tris), origins, dirs)
    boxes = raycast.closest_hits(raycast.build_grid(tris, raycast.FEW_RAYS_CELLS_PER_TRIANGLE,
                                                    exact=False), origins, dirs)
    assert np.array_equal(exact[0], boxes[0])  # the same distances: the same hit points
    # the same triangles, but where a ray meets the edge two triangles share (either counts)
    other = exact[1] != boxes[1]
    assert other.mean() < 0.01
    assert np.isfinite(exact[0]).mean() > 0.5

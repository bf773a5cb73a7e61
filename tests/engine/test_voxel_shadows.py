"""Shadow rays through cascade occupancy."""
import numpy as np

from voxgi.voxgi_addon.gi.cascades import CascadeGrid, CascadeVoxels
from voxgi.voxgi_addon.gi.voxel_shadows import CascadeOccupancy


def voxels(grid, cells):
    n = len(cells)
    return CascadeVoxels(grid, np.asarray(cells, np.int32), np.zeros((n, 3)), np.tile([0, 0, 1.0], (n, 1)),
                         np.zeros(n), np.ones(n, np.int32), np.zeros(n, bool))


def two_cascades(wall_x_cells):
    fine = CascadeGrid(0, 0.1, 16, np.array([-0.8, -0.8, -0.8]))
    coarse = CascadeGrid(1, 0.2, 16, np.array([-1.6, -1.6, -1.6]))
    yz = np.stack(np.meshgrid(np.arange(16), np.arange(16), indexing="ij"), -1).reshape(-1, 2)
    wall = np.column_stack([np.full(len(yz), wall_x_cells), yz])
    return [voxels(fine, wall), voxels(coarse, np.zeros((0, 3), int))]


def test_a_wall_blocks_rays_that_cross_it_and_only_those():
    occ = CascadeOccupancy(two_cascades(wall_x_cells=10))  # fine cells x=10 → x ∈ [0.2, 0.3)
    origins = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]])
    dirs = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    blocked = occ.occluded(origins, dirs, np.array([2.0, 0.6, 2.0]))
    assert blocked.tolist() == [True, False, False]


def test_points_outside_every_cascade_are_free_and_local_span_picks_the_finest():
    occ = CascadeOccupancy(two_cascades(wall_x_cells=10))
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    assert occ.local_span(pts).tolist() == [0.1, 0.2, np.inf]
    assert not occ.occupied(pts).any()
    assert occ.occupied(np.array([[0.25, 0.0, 0.0]])).all()

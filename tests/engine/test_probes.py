"""Light probes (docs/probes.md): SH, placement, masks, validity, bake and query."""
import math

import numpy as np
import pytest
from probe_scenes import cornell_box, thin_wall_room

from voxgi.voxgi_addon.probes import sh
from voxgi.voxgi_addon.probes.bake import ProbeSettings, bake_probe_grid
from voxgi.voxgi_addon.probes.grid import DISABLED, NO_INDEX, RELOCATED, ProbeGrid, memory_report
from voxgi.voxgi_addon.probes.masks import path_search
from voxgi.voxgi_addon.probes.placement import place_probes
from voxgi.voxgi_addon.probes.query import query_irradiance
from voxgi.voxgi_addon.probes.validity import relocate_probes
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.voxelize.triangle_box import triangle_overlaps_cells

# --------------------------------------------------------------------------- SH


def test_constant_radiance_projects_to_the_dc_term_and_gives_pi_l():
    dirs = sh.sample_directions(256, seed=3)
    c = sh.project(np.full((256, 3), [1.0, 2.0, 0.5]), dirs)
    np.testing.assert_allclose(c[0], 2 * math.sqrt(math.pi) * np.array([1.0, 2.0, 0.5]), rtol=1e-12)
    np.testing.assert_allclose(c[1:], 0.0, atol=0.02)
    normals = sh.sample_directions(50, seed=9)
    exact = np.zeros((9, 1))
    exact[0] = 2 * math.sqrt(math.pi) * 0.7  # L = 0.7
    np.testing.assert_allclose(sh.irradiance(exact, normals), math.pi * 0.7, rtol=1e-12)


def test_clamped_cosine_lobe_has_the_known_zonal_coefficients():
    dirs = sh.sample_directions(8192, seed=1)
    c = sh.project(np.maximum(dirs[:, 2], 0.0)[:, None], dirs)[:, 0]
    expected = np.zeros(9)
    expected[0] = math.sqrt(math.pi) / 2          # 0.886227
    expected[2] = math.sqrt(math.pi / 3)          # 1.023327
    expected[6] = math.sqrt(5 * math.pi) / 8      # 0.495416
    np.testing.assert_allclose(c, expected, atol=2e-3)


def test_one_direction_projects_to_the_basis_and_its_irradiance_is_the_lobe():
    d = np.array([0.3, -0.5, 0.81])
    d /= np.linalg.norm(d)
    c = sh.project_direction(d, [2.0])
    np.testing.assert_allclose(c[:, 0], 2.0 * sh.sh_basis(d[None])[0])
    assert sh.sh_basis(d[None])[0, 3] == pytest.approx(0.488603 * d[0], rel=1e-5)
    # A Dirac of power 1 along d: E(n) = max(0, n·d), approximated by L2 (worst case ~0.1 absolute).
    normals = sh.sample_directions(200, seed=2)
    e = sh.irradiance(sh.project_direction(d, 1.0), normals)[:, 0]
    cos = np.maximum(normals @ d, 0.0)
    assert np.abs(e - cos).max() < 0.2 and e[np.argmax(cos)] == pytest.approx(1.0, abs=0.12)


def test_sample_directions_are_unit_uniform_and_fixed_by_the_seed():
    a, b, c = (sh.sample_directions(512, s) for s in (4, 4, 5))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0)
    np.testing.assert_allclose(a.mean(axis=0), 0.0, atol=2e-3)
    # Second moments of a uniform sphere: E[x x^T] = I/3.
    np.testing.assert_allclose(a.T @ a / len(a), np.eye(3) / 3, atol=3e-3)


# --------------------------------------------------------------------------- placement

def _slabs(k):
    """Planes z = (i + ½)/k, i < k, filling the unit cube: every volume of a k-grid has geometry."""
    tris = []
    for i in range(k):
        z = (i + 0.5) / k
        tris += [[(0, 0, z), (1, 0, z), (1, 1, z)], [(0, 0, z), (1, 1, z), (0, 1, z)]]
    t = np.array(tris, np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return t, n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("k", [1, 3, 4])
def test_a_full_grid_has_k_plus_1_cubed_probes_and_64_mask_bytes_per_volume(k):
    t, n = _slabs(k)
    layout = place_probes(t, n, (0, 0, 0), (1, 1, 1), k)
    assert len(layout.volume_cells) == k**3
    assert len(layout.positions) == (k + 1) ** 3
    grid = ProbeGrid(layout.origin, layout.volume_size, layout.dims, layout.positions,
                     np.zeros((len(layout.positions), 9, 3)), layout.volume_cells.astype(np.uint32),
                     layout.volume_probes.astype(np.uint32), np.zeros((k**3, 8), np.uint64))
    report = memory_report(grid)
    assert report["occlusion_masks"] == 64 * k**3
    assert report["sh_index"] == 4 * (k + 1) ** 3 and report["occlusion_index"] == 4 * k**3
    assert report["sh_coefficients"] == 27 * 4 * (k + 1) ** 3


def test_active_volumes_are_exactly_those_a_triangle_touches():
    snap = cornell_box()
    tris = world_triangles(snap)
    k = 5
    lo, hi = np.array([-1.2, -1.1, -0.1]), np.array([1.3, 1.2, 2.1])
    layout = place_probes(tris.positions, tris.normals, lo, hi, k)
    size = (hi - lo) / k
    cells = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), -1).reshape(-1, 3)
    hit = np.zeros(len(cells), bool)
    for tri in tris.positions:
        hit |= triangle_overlaps_cells((tri - lo) / size, cells)
    expected = np.sort(cells[hit, 0] + k * (cells[hit, 1] + k * cells[hit, 2]))
    np.testing.assert_array_equal(layout.volume_cells, expected)
    # Probes are shared: every corner position appears once.
    assert len(np.unique(layout.positions.round(9), axis=0)) == len(layout.positions)
    assert len(layout.positions) < 8 * len(layout.volume_cells)


# --------------------------------------------------------------------------- masks and validity

def test_path_search_stops_at_a_blocked_layer():
    open_all = np.ones((1, 8, 64), bool)
    assert (path_search(open_all) == np.uint64(2**64 - 1)).all()
    blocked = np.ones((1, 8, 64), bool)
    sx = np.arange(64) % 4
    blocked[:, :, sx == 2] = False  # a wall through sub-volume column x = 2
    masks = path_search(blocked)
    bits = ((masks[0, :, None] >> np.arange(64, dtype=np.uint64)) & np.uint64(1)).astype(bool)
    for c in range(8):
        lit = np.flatnonzero(bits[c])
        if c & 1:  # corner at x = 1: reaches x = 3 only
            assert set(sx[lit]) == {3}
        else:
            assert set(sx[lit]) == {0, 1}


def test_probe_inside_a_closed_box_is_relocated_out_or_disabled():
    from probe_scenes import box_mesh

    from voxgi.voxgi_addon.scene.snapshot import ObjectData, SceneSnapshot

    snap = SceneSnapshot({"B": box_mesh("B", (-0.1, -0.1, -0.1), (0.1, 0.1, 0.1))}, [],
                         [ObjectData("B", "B", np.eye(4))])
    tris = world_triangles(snap)
    dirs = sh.sample_directions(64, 0)
    p = np.array([[0.0, 0.0, 0.02], [0.0, 0.0, 0.5]])
    pos, validity, flags, _ = relocate_probes(tris, p, dirs, 0.25, max_offset=0.5, step=0.05)
    assert flags[0] & RELOCATED and not flags[0] & DISABLED
    assert np.abs(pos[0]).max() > 0.1 and validity[0] == 0  # outside the box, sees no back face
    assert flags[1] == 0 and np.array_equal(pos[1], p[1])
    pos, validity, flags, _ = relocate_probes(tris, p, dirs, 0.25, max_offset=0.05, step=0.05)
    assert flags[0] & DISABLED and validity[0] == 1.0


# --------------------------------------------------------------------------- bake and query

def _grid_with_dc(values, k=2):
    """A full k-grid over the unit cube whose probe i has constant radiance values[i] (RGB)."""
    t, n = _slabs(k)
    layout = place_probes(t, n, (0, 0, 0), (1, 1, 1), k)
    shc = np.zeros((len(layout.positions), 9, 3), np.float32)
    shc[:, 0] = 2 * math.sqrt(math.pi) * np.asarray(values)
    return ProbeGrid(layout.origin, layout.volume_size, layout.dims, layout.positions, shc,
                     layout.volume_cells.astype(np.uint32), layout.volume_probes.astype(np.uint32),
                     np.full((k**3, 8), 2**64 - 1, np.uint64))


def test_query_interpolates_trilinearly_through_the_index_arrays():
    k = 2
    t, n = _slabs(k)
    positions = place_probes(t, n, (0, 0, 0), (1, 1, 1), k).positions
    radiance = positions @ np.array([1.0, 2.0, 3.0]) + 0.5  # linear in space: trilinear is exact
    grid = _grid_with_dc(np.repeat(radiance[:, None], 3, axis=1), k)
    rng = np.random.default_rng(0)
    points = rng.random((1000, 3))
    normals = sh.sample_directions(1000, 1)
    e = query_irradiance(grid, points, normals)
    expected = math.pi * (points @ np.array([1.0, 2.0, 3.0]) + 0.5)
    np.testing.assert_allclose(e[:, 1], expected, rtol=1e-5)
    assert (grid.sh_index != NO_INDEX).sum() == len(grid.positions)
    # A disabled probe drops out: the others' weights are renormalised.
    grid.flags[:] = 0
    grid.flags[0] = DISABLED
    near = np.array([[0.01, 0.01, 0.01]])
    assert query_irradiance(grid, near, [[0, 0, 1.0]])[0, 0] > math.pi * 0.5 * 1.05


def test_bake_is_deterministic_and_a_cornell_probe_sees_the_red_wall():
    settings = ProbeSettings(resolution=4, directions=128, seed=7)
    a = bake_probe_grid(cornell_box(), settings).grid
    b = bake_probe_grid(cornell_box(), settings).grid
    np.testing.assert_array_equal(a.sh, b.sh)
    np.testing.assert_array_equal(a.volume_masks, b.volume_masks)
    c = bake_probe_grid(cornell_box(), ProbeSettings(resolution=4, directions=128, seed=8)).grid
    assert not np.array_equal(a.sh, c.sh)
    # Near the red wall (x = -1) facing it, irradiance is red; near the green wall, green.
    e = query_irradiance(a, [[-0.9, 0.0, 1.0], [0.9, 0.0, 1.0]], [[-1, 0, 0], [1, 0, 0.0]])
    assert e[0, 0] > 3 * e[0, 1] and e[1, 1] > 3 * e[1, 0]


def test_a_triangle_with_a_nan_corner_changes_no_probe():
    """A broken triangle (a NaN corner, as a bad import leaves) is hit by no ray and spans no
    box: the probes bake as without it (the bake once stopped: "the probe box [nan nan nan]
    .. [nan nan nan] is empty")."""
    from voxgi.voxgi_addon.scene.geometry import SceneTriangles

    snapshot = cornell_box()
    tris = world_triangles(snapshot)
    broken = np.array([[[0.2, 0.1, 0.5], [float("nan"), 0.3, 0.5], [0.1, 0.4, 0.9]]])
    with_broken = SceneTriangles(np.concatenate([tris.positions, broken]),
                                 np.concatenate([tris.normals, [[0.0, 0.0, 1.0]]]),
                                 np.concatenate([tris.materials, [0]]).astype(np.int32),
                                 np.concatenate([tris.objects, [0]]).astype(np.int32))
    settings = ProbeSettings(resolution=3, directions=64, seed=2)
    clean = bake_probe_grid(snapshot, settings, tris=tris).grid
    grid = bake_probe_grid(snapshot, settings, tris=with_broken).grid
    assert np.isfinite(grid.sh).all()
    np.testing.assert_allclose(grid.positions, clean.positions)
    np.testing.assert_allclose(grid.sh, clean.sh, rtol=1e-6, atol=1e-7)


def test_a_stray_object_far_away_leaves_the_probes_where_the_room_is():
    """A 5 cm cube 170 m from the Cornell box (a stray helper) would stretch the probe box and
    every volume over the empty space between; the box stands for the bulk of the triangles'
    area (``scene.geometry.bulk_bounds``), so the probes stand where they stood without it."""
    from voxgi.voxgi_addon.scene.geometry import SceneTriangles

    snapshot = cornell_box()
    tris = world_triangles(snapshot)
    cube = np.array([[[100.0, 100.0, 100.0], [100.05, 100.0, 100.0], [100.0, 100.05, 100.0]],
                     [[100.0, 100.0, 100.0], [100.0, 100.05, 100.0], [100.0, 100.0, 100.05]]])
    with_stray = SceneTriangles(np.concatenate([tris.positions, cube]),
                                np.concatenate([tris.normals, [[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]]]),
                                np.concatenate([tris.materials, [0, 0]]).astype(np.int32),
                                np.concatenate([tris.objects, [0, 0]]).astype(np.int32))
    settings = ProbeSettings(resolution=3, directions=64, seed=2)
    clean = bake_probe_grid(snapshot, settings, tris=tris).grid
    grid = bake_probe_grid(snapshot, settings, tris=with_stray).grid
    assert grid.positions.shape == clean.positions.shape
    np.testing.assert_allclose(grid.positions, clean.positions, atol=0.02 * np.ptp(clean.positions))


def _thin_wall_ratio(use_masks):
    grid = bake_probe_grid(thin_wall_room(), ProbeSettings(resolution=8, directions=128,
                                                           use_masks=use_masks)).grid
    x, y = np.meshgrid(np.linspace(-1.85, 1.85, 75), np.linspace(-0.85, 0.85, 19))
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    e = query_irradiance(grid, points, np.tile([0, 0, 1.0], (len(points), 1)), use_masks).mean(axis=1)
    return e[points[:, 0] > 0.15].max() / e[points[:, 0] < -0.15].mean()


def test_masks_keep_the_light_on_its_side_of_a_thin_wall():
    with_masks, without = _thin_wall_ratio(True), _thin_wall_ratio(False)
    print(f"thin wall, dark max / lit mean: masks {with_masks:.4f}, no masks {without:.4f}")
    assert with_masks < 0.02
    assert without > 0.005 and without > 5 * with_masks


# --------------------------------------------------------------------------- files

def _baked():
    return bake_probe_grid(cornell_box(), ProbeSettings(resolution=3, directions=64)).grid


def test_probe_grids_survive_gfg_and_the_compact_store_and_answer_the_same_queries():
    from voxgi.voxgi_addon.files.gfg import GFGScene, read_gfg, to_bytes
    from voxgi.voxgi_addon.probes.store import from_text, to_text

    grid = _baked()
    points = np.random.default_rng(1).uniform([-1, -1, 0], [1, 1, 2], (500, 3))
    normals = sh.sample_directions(500, 3)
    expected = query_irradiance(grid, points, normals)
    back = read_gfg(to_bytes(GFGScene(probe_grids=[grid]))).probe_grids[0]
    stored = from_text(to_text([grid]))[0]
    for other in (back, stored):
        for f in ("origin", "volume_size", "dims", "positions", "sh", "volume_cells", "volume_probes",
                  "volume_masks", "sh_index", "mask_index", "validity", "flags"):
            np.testing.assert_array_equal(np.asarray(getattr(other, f)), np.asarray(getattr(grid, f)))
        np.testing.assert_array_equal(query_irradiance(other, points, normals), expected)
    assert len(to_text([grid])) < 4 * 1024 + 2 * len(grid.positions) * 27 * 4


def test_a_format_1_1_probe_section_is_still_read():
    """GFG 1.1 wrote a 56-byte PRBG info (one cell size) and five arrays; 1.2 rebuilds the rest."""
    import io
    import struct
    import zlib

    from voxgi.voxgi_addon.files.gfg import GFGScene, read_gfg
    from voxgi.voxgi_addon.files.gfg import data_types as dtypes
    from voxgi.voxgi_addon.files.gfg.container import SectionBuilder, write_container
    from voxgi.voxgi_addon.files.gfg.spec import PROBE_GRID_INFO_1_1, Kind, Role

    grid = _baked()
    grid.volume_size[:] = grid.volume_size[0]  # 1.1 grids had cubic volumes
    p, v = len(grid.positions), len(grid.volume_cells)
    info = np.array([(grid.origin, grid.volume_size[0], grid.dims, p, v, 9)], PROBE_GRID_INFO_1_1)
    s = SectionBuilder(Kind.PROBE_GRID, info)
    f3, u32, u64 = (dtypes.code_of(n) for n in ("FLOAT_3", "UINT32_1", "UINT64_1"))
    s.add(Role.PROBE_POSITIONS, f3, np.asarray(grid.positions, "<f4"))
    s.add(Role.PROBE_SH, f3, np.asarray(grid.sh, "<f4").reshape(-1, 3))
    s.add(Role.VOLUME_CELLS, u32, np.asarray(grid.volume_cells, "<u4"))
    s.add(Role.VOLUME_PROBES, u32, np.asarray(grid.volume_probes, "<u4").ravel())
    s.add(Role.VOLUME_MASKS, u64, np.asarray(grid.volume_masks, "<u8").ravel())
    stream = io.BytesIO()
    write_container(stream, [s])
    data = bytearray(stream.getvalue())
    data[10:12] = struct.pack("<H", 1)  # format 1.1
    struct.pack_into("<I", data, 60, zlib.crc32(bytes(data[:60])))
    back = read_gfg(bytes(data))
    assert back.version == (1, 1) and isinstance(back, GFGScene)
    old = back.probe_grids[0]
    np.testing.assert_array_equal(old.sh_index, grid.sh_index)
    np.testing.assert_array_equal(old.mask_index, grid.mask_index)
    np.testing.assert_array_equal(old.volume_size, grid.volume_size)
    assert old.mask_threshold == 0.5 and not old.flags.any()


def test_the_documented_numpy_loader_reads_the_probe_sections(tmp_path):
    """The example in docs/gfg.md "PRBG", run as written, on a file with two grids."""
    import pathlib
    import re

    from voxgi.voxgi_addon.files.gfg import GFGScene, write_gfg

    doc = (pathlib.Path(__file__).resolve().parents[2] / "docs" / "gfg.md").read_text()
    code = re.search(r"```python\n(import struct, numpy as np\n.*?)```", doc, re.S).group(1)
    namespace = {}
    exec(compile(code, "docs/gfg.md", "exec"), namespace)
    grids = [_baked(), bake_probe_grid(cornell_box(), ProbeSettings(resolution=(2, 3, 4), directions=16)).grid]
    path = tmp_path / "probes.gfg"
    write_gfg(path, GFGScene(probe_grids=grids))
    loaded = namespace["read_probe_grids"](str(path))
    assert len(loaded) == 2
    for got, grid in zip(loaded, grids):
        for f in ("origin", "volume_size", "dims", "positions", "sh", "volume_cells", "volume_probes",
                  "volume_masks", "sh_index", "mask_index"):
            np.testing.assert_array_equal(got[f], np.asarray(getattr(grid, f)).astype(got[f].dtype))


def test_probes_see_the_world_map_and_are_lit_by_it():
    """A floor under a sky map that is blue above and dark below the horizon (no lamp): a probe
    above the floor sees the map where its rays miss (its upward irradiance is the sky's π·L
    over the hemisphere), and the floor it sees below is lit by the sky (not black)."""
    from voxgi.voxgi_addon.scene.equirect import pixel_directions
    from voxgi.voxgi_addon.scene.snapshot import MaterialData, MeshData, ObjectData, SceneSnapshot, WorldData

    d = pixel_directions(16, 32)
    sky = np.where(d[..., 2:] > 0, np.array([0.2, 0.4, 0.9]), 0.0).astype(np.float32)
    floor = MeshData("Floor", np.array([(-50, -50, 0), (50, -50, 0), (50, 50, 0), (-50, 50, 0)],
                                       np.float32), np.array([(0, 1, 2), (0, 2, 3)], np.int32),
                     np.zeros(2, np.int32))
    snapshot = SceneSnapshot({"Floor": floor}, [MaterialData("grey", np.array([0.5] * 3, np.float32))],
                             [ObjectData("Floor", "Floor", np.eye(4))],
                             world=WorldData(np.array([0.1, 0.2, 0.45], np.float32), 1.0, sky, "sky"))
    grid = bake_probe_grid(snapshot, ProbeSettings(resolution=2, directions=256, seed=1),
                           box=((-1, -1, -0.5), (1, 1, 1.5))).grid
    up, down = query_irradiance(grid, [[0.0, 0.0, 1.0]] * 2, [[0, 0, 1.0], [0, 0, -1.0]])
    np.testing.assert_allclose(up, math.pi * np.array([0.2, 0.4, 0.9]), rtol=0.1)
    # the floor (albedo 0.5) lit by the whole sky: radiance 0.5 × L, so irradiance ≈ π × that
    np.testing.assert_allclose(down, math.pi * 0.5 * np.array([0.2, 0.4, 0.9]), rtol=0.15)

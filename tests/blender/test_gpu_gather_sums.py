"""The GPU gather sums (render/gpu_gather_sums.py, render/shaders/gather_sums.glsl) equal their
numpy reference, voxgi_addon/preview/progressive.py GatherSums."""
from __future__ import annotations

import numpy as np
import pytest

RTOL, ATOL = 1e-4, 1e-6


@pytest.fixture
def gpu_tools(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture

    ready, why = ensure_gpu_context()
    assert ready, why

    def upload(array):
        """A GL texture (row 0 at the bottom) of the (h, w, 4) array (row 0 on top)."""
        return float_texture(np.flipud(array), (array.shape[1], array.shape[0]))

    def download(texture):
        return np.flipud(read_texture(texture))
    return upload, download


def _gather(rng, low_h, low_w, nans: bool):
    values = rng.uniform(0.0, 1.0, (low_h, low_w, 4))
    variance = rng.uniform(0.0, 0.05, (low_h, low_w, 4))
    # .z: −the points' reach (bvh_gather.glsl), 0 where every ray missed
    variance[..., 2] = np.where(rng.random((low_h, low_w)) < 0.2, 0.0,
                                -rng.uniform(0.05, 3.0, (low_h, low_w)))
    if nans:  # cells of no surface
        values[rng.random((low_h, low_w)) < 0.15] = np.nan
        variance[rng.random((low_h, low_w)) < 0.15] = np.nan
        values[rng.random((low_h, low_w, 4)) < 0.05] = np.nan
    return values.astype(np.float32), variance.astype(np.float32)


def test_gpu_gather_sums_equal_numpy(gpu_tools):
    from voxgi.render.gpu_gather_sums import GPUGatherSums
    from voxgi.voxgi_addon.preview.progressive import GatherSums, tile_grid
    from voxgi.voxgi_addon.preview.upsample import low_shape

    upload, download = gpu_tools
    width, height, stride = 45, 29, 2  # 23 × 15 cells; tiles of 6 × 5 cells reach past it
    reference, sums = GatherSums(width, height, stride), GPUGatherSums(width, height, stride)
    rng = np.random.default_rng(7)
    kinds = {"diffuse": 1, "glossy": 4, "behind diffuse": 1, "world glossy": 2}
    shifts = [(0, 0), (4, 6), (8, 2), (2, 4)]  # the samples' grids: tiles at negative x0, y0 too
    checked = 0
    for sample, shift in enumerate(shifts):
        tiles = tile_grid(width, height, 12, 10, shift)
        assert any(x0 < 0 or y0 < 0 for x0, y0, _, _ in tiles) == (shift != (0, 0))
        assert any(x0 + w > width or y0 + h > height for x0, y0, w, h in tiles)
        for rect in tiles:
            low_h, low_w = low_shape(rect[3], rect[2], stride)
            for kind, rays in kinds.items():
                values, variance = _gather(rng, low_h, low_w, nans=sample % 2 == 1)
                ref_mean, ref_pooled = reference.add(kind, rect, values, variance, rays)
                mean, pooled = sums.add(kind, rect, upload(values), upload(variance), rays)
                assert (mean.width, mean.height) == (low_w, low_h)
                assert (pooled.width, pooled.height) == (low_w, low_h)
                mean, pooled = download(mean), download(pooled)
                assert np.isfinite(mean).all() and np.isfinite(pooled).all()
                np.testing.assert_allclose(mean, ref_mean, rtol=RTOL, atol=ATOL,
                                           err_msg=f"{kind} {rect} sample {sample}")
                np.testing.assert_allclose(pooled, ref_pooled, rtol=RTOL, atol=ATOL,
                                           err_msg=f"{kind} {rect} sample {sample}")
                checked += 1
    assert checked == len(kinds) * sum(len(tile_grid(width, height, 12, 10, s)) for s in shifts)
    # samples after the gathering ones trace no rays: every tile reads the sums (its cells past
    # the image the nearest cell's), twice the same — nothing was added
    for rect in tile_grid(width, height, 12, 10, (6, 4)):
        low_h, low_w = low_shape(rect[3], rect[2], stride)
        for kind in kinds:
            ref_mean, ref_pooled = reference.add(kind, rect, None, None, 0)
            assert (ref_mean.shape[0], ref_mean.shape[1]) == (low_h, low_w)
            blank = upload(np.zeros((low_h, low_w, 4), np.float32))
            for _ in range(2):
                mean, pooled = (download(t) for t in sums.add(kind, rect, blank, blank, 0))
                np.testing.assert_allclose(mean, ref_mean, rtol=RTOL, atol=ATOL)
                np.testing.assert_allclose(pooled, ref_pooled, rtol=RTOL, atol=ATOL)
            again, _ = reference.add(kind, rect, None, None, 0)
            np.testing.assert_array_equal(again, ref_mean)
            x0, y0 = rect[0] // stride, rect[1] // stride
            row, col = min(max(y0, 0), reference.shape[0] - 1), min(max(x0, 0), reference.shape[1] - 1)
            totals = reference.kinds[kind]
            np.testing.assert_allclose(  # the tile's first cell: the image's nearest cell's mean
                ref_mean[0, 0], totals["values"][row, col] / totals["n"][row, col], rtol=1e-5)
    sums.free()
    assert not sums.sums


def test_gpu_gather_sums_cells_and_kinds(gpu_tools):
    """By hand: a tile not at the image's origin and one reaching past the border share cells
    (the flips), the spread rule with one ray, the kinds apart, past the image the tile's own."""
    from voxgi.render.gpu_gather_sums import GPUGatherSums
    from voxgi.render.gpu_tracer import read_texture

    upload, download = gpu_tools
    sums = GPUGatherSums(10, 9, 2)  # 5 × 5 cells
    a = np.zeros((2, 3, 4), np.float32)  # tile (4, 2, 6, 4): cells rows 1–2, columns 2–4
    a[0, 0] = (1.0, 1.0, 1.0, 0.5)  # cell (row 1, column 2)
    a[1, 2] = (0.2, 0.2, 0.2, 0.0)  # cell (row 2, column 4)
    var_a = np.full((2, 3, 4), 0.04, np.float32)
    var_a[..., 2] = -0.5  # −the points' reach (bvh_gather.glsl): 0.5 m, not handed on
    mean, pooled = sums.add("diffuse", (4, 2, 6, 4), upload(a), upload(var_a), 1)
    no_reach = np.array([1.0, 1.0, 0.0, 1.0], np.float32)  # the view's filter takes none
    assert np.allclose(download(mean), a) and np.allclose(download(pooled), var_a * no_reach)

    b = np.zeros((3, 3, 4), np.float32)  # tile (2, 0, 6, 6): cells rows 0–2, columns 1–3
    b[1, 1] = (3.0, 3.0, 3.0, 1.5)  # cell (row 1, column 2), as a[0, 0]
    b[2, 2] = (np.nan, 0.0, 0.0, 0.0)  # cell (row 2, column 3): NaN as 0
    var_b = np.full((3, 3, 4), 0.08, np.float32)
    var_b[..., 2] = -0.25
    mean, pooled = sums.add("diffuse", (2, 0, 6, 6), upload(b), upload(var_b), 1)
    mean, pooled = download(mean), download(pooled)
    assert np.allclose(mean[1, 1], (2.0, 2.0, 2.0, 1.0))
    # one ray: the luminance's is the samples' spread (luminances 1 and 3): (10 / 2 − 2²) / 1
    assert np.allclose(pooled[1, 1], (1.0, 0.12 / 4, 0.0, 0.12 / 4))
    assert np.allclose(mean[2, 2], 0.0) and np.allclose(pooled[2, 2, 1:], (0.03, 0.0, 0.03))
    assert np.allclose(mean[0, 0], 0.0) and np.allclose(pooled[0, 0], (0.08, 0.08, 0.0, 0.08))
    # the storage: Σ values, Σ variances, (Σ luminance², count) stacked, each layer in GL rows
    storage = read_texture(sums.sums["diffuse"])
    assert storage.shape == (15, 5, 4)
    layers = [np.flipud(storage[5 * k:5 * (k + 1)]) for k in range(3)]
    assert np.allclose(layers[0][1, 2], (4.0, 4.0, 4.0, 2.0))
    assert np.allclose(layers[1][1, 2, [0, 1, 3]], 0.12)
    assert np.allclose(layers[2][1, 2], (10.0, 2.0, 0.0, 0.0))
    assert np.allclose(layers[2][..., 1], [[0, 1, 1, 1, 0], [0, 1, 2, 2, 1], [0, 1, 2, 2, 1]] + [[0] * 5] * 2)

    c = np.full((4, 2, 4), 5.0, np.float32)  # tile (8, 4, 4, 8): column 5 and row 5 are past it
    var_c = np.full((4, 2, 4), 0.5, np.float32)
    var_c[..., 2] = -2.0
    mean, pooled = sums.add("diffuse", (8, 4, 4, 8), upload(c), upload(var_c), 3)
    mean, pooled = download(mean), download(pooled)
    assert np.allclose(mean[:, 1], 5.0) and np.allclose(pooled[:, 1], var_c[:, 1])  # past the image
    assert np.allclose(mean[3], 5.0) and np.allclose(pooled[3], var_c[0])
    assert np.allclose(mean[0, 0], (2.6, 2.6, 2.6, 2.5))  # cell (row 2, column 4), with a[1, 2]
    assert np.allclose(pooled[0, 0], (0.54 / 4, 0.54 / 4, 0.0, 0.54 / 4))  # rays > 1: pooled
    assert np.allclose(mean[1, 0], 5.0) and np.allclose(pooled[1, 0], var_c[0, 0] * no_reach)

    mean, pooled = sums.add("glossy", (2, 0, 6, 6), upload(b), upload(var_b), 1)
    assert np.allclose(download(mean)[1, 1], (3.0, 3.0, 3.0, 1.5))  # a kind of its own
    assert np.allclose(download(pooled)[1, 1], var_b[0, 0] * no_reach)


def test_gpu_gather_sums_errors(gpu_tools):
    from voxgi.render.gpu_gather_sums import GPUGatherSums

    upload, _ = gpu_tools
    sums = GPUGatherSums(20, 20, 4)
    cells = upload(np.zeros((2, 3, 4), np.float32))
    with pytest.raises(ValueError, match="stride-4 block"):
        sums.add("diffuse", (2, 0, 12, 8), cells, cells, 1)
    with pytest.raises(ValueError, match="3×2 gather for a tile of 3×3 cells"):
        sums.add("diffuse", (0, 0, 12, 12), cells, cells, 1)
    with pytest.raises(ValueError, match="3×2 gather for a tile of 3×3 cells"):
        sums.add("diffuse", (0, 0, 12, 12), upload(np.zeros((3, 3, 4), np.float32)), cells, 1)
    assert not sums.sums  # nothing allocated for a refused tile


def test_gpu_lattice_gather_sums_equal_numpy(gpu_tools):
    """A sample gathered at the lattice only (the view's first: ``lattice``) adds the same
    cells and leaves the same holes on the GPU as in numpy, tiles past the image and of odd
    sizes included; the next sample at every cell fills them."""
    from voxgi.render.gpu_gather_sums import GPUGatherSums
    from voxgi.voxgi_addon.preview.progressive import GatherSums, tile_grid
    from voxgi.voxgi_addon.preview.upsample import low_shape

    upload, download = gpu_tools
    width, height, stride = 31, 23, 1
    reference, sums = GatherSums(width, height, stride), GPUGatherSums(width, height, stride)
    rng = np.random.default_rng(11)
    holes = 0
    for sample, (shift, lattice) in enumerate((((3, 2), True), ((0, 5), False))):
        for rect in tile_grid(width, height, 9, 7, shift):
            low_h, low_w = low_shape(rect[3], rect[2], stride)
            given = low_shape(low_h, low_w, 2) if lattice else (low_h, low_w)
            values, variance = _gather(rng, *given, nans=True)
            variance[..., 2:] = 0.0
            ref_mean, ref_pooled = reference.add("diffuse", rect, values, variance, 4,
                                                 lattice=lattice)
            mean, pooled = sums.add("diffuse", rect, upload(values), upload(variance), 4,
                                    lattice=lattice)
            mean, pooled = download(mean), download(pooled)
            assert mean.shape[:2] == (low_h, low_w)
            np.testing.assert_allclose(mean, ref_mean, rtol=RTOL, atol=ATOL,
                                       err_msg=f"{rect} sample {sample}")
            np.testing.assert_allclose(pooled, ref_pooled, rtol=RTOL, atol=ATOL,
                                       err_msg=f"{rect} sample {sample}")
            holes += int((pooled[..., 2] == 1.0).sum()) if lattice else 0
            assert lattice or not (pooled[..., 2] == 1.0).any()
    assert holes > width * height // 2

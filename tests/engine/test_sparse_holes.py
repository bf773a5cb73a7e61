"""The sparse gather's second list (``noisy_holes``): the holes whose fill would be furthest
off, by the noise of their traced neighbours and by a light's edge among them."""
import numpy as np

from voxgi.voxgi_addon.preview.sparse_gather import EXTRA, noisy_holes


def _lattice_with_band(h=24, w=40, band_row=11):
    """The first list over a plane: odd rows and odd columns, and a band one cell tall (its
    cells traced whole) lit 10× the rest, whose traced cells all have the same noise."""
    rows, cols = np.indices((h, w))
    band = rows == band_row
    traced = ((rows % 2 == 1) & (cols % 2 == 1)) | band
    light = np.where(band, 3.0, 0.3)[..., None] * np.ones(3)
    variance = np.full((h, w), 1e-4)
    return traced, light, variance, rows, band_row


def test_the_holes_beside_a_lit_band_are_traced_first():
    """With the traced cells' noise alike everywhere, the holes picked are those beside the
    band (rows band ± 1), whose 3 × 3 neighbours lie on both sides of the light's edge."""
    traced, light, variance, rows, band_row = _lattice_with_band()
    valid = np.ones(traced.shape, bool)
    picked = noisy_holes(traced, valid, variance, light)
    assert picked.sum() == int(EXTRA * valid.sum())
    assert not (picked & traced).any()
    assert np.all(np.abs(rows[picked] - band_row) == 1), np.unique(rows[picked])


def test_without_the_light_the_noise_alone_ranks_the_holes():
    """Given no light, the ranking is the fill's noise: the holes with the fewest traced
    neighbours (the band's own are many) come first, wherever the light's edge is."""
    traced, light, variance, rows, band_row = _lattice_with_band()
    valid = np.ones(traced.shape, bool)
    picked = noisy_holes(traced, valid, variance)
    assert picked.sum() == int(EXTRA * valid.sum())
    assert not np.all(np.abs(rows[picked] - band_row) == 1)


def test_one_neighbours_rare_bright_ray_does_not_pick_the_holes_around_it():
    """A traced cell that caught a rare bright ray (light 10×, variance 100× its neighbours')
    does not draw the second list to the holes around it, which would leave the holes not
    picked filled from the dimmer cells (the image's light short); the holes of a region whose
    traced cells are all noisier are picked instead."""
    h, w = 24, 40
    rows, cols = np.indices((h, w))
    traced = (rows % 2 == 1) & (cols % 2 == 1)
    light = np.full((h, w, 3), 0.3)
    variance = np.full((h, w), 1e-4)
    variance[:, 30:] = 4e-4  # a noisier region
    light[11, 11], variance[11, 11] = 3.0, 1e-2  # the rare bright ray
    picked = noisy_holes(traced, np.ones((h, w), bool), variance, light)
    assert picked.sum() == int(EXTRA * h * w)
    beside = (np.abs(rows - 11) <= 1) & (np.abs(cols - 11) <= 1)
    assert not (picked & beside).any()
    assert np.all(cols[picked] >= 29)


def test_the_glossy_gather_is_sparse_where_its_cells_are_pixels_and_its_light_not_all():
    """With Sparse Gathers, at a cell per pixel the glossy gather traces the diffuse gather's
    plan and every cell of a full metal (all its light is glossy); at a cell per 3 × 3 pixels,
    or with Sparse Gathers off, every cell."""
    from voxgi.voxgi_addon.preview.sparse_gather import SPARSE_GLOSSY_STRIDE, glossy_cells

    h, w = 12, 16
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    position = np.stack([xs * 0.02, ys * 0.02, np.zeros_like(xs)], axis=-1)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    valid = np.ones((h, w), bool)
    diffuse = xs < 8  # the right half a full metal
    traced = glossy_cells(valid, position, normal, SPARSE_GLOSSY_STRIDE, True, diffuse)
    assert traced[~diffuse].all()
    assert traced[diffuse].mean() < 0.3  # one cell in four on the plane
    assert glossy_cells(valid, position, normal, 3, True, diffuse).all()
    assert glossy_cells(valid, position, normal, 1, False, diffuse).all()

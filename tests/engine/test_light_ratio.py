"""Light passes are divided as Cycles' film divides them (``preview.passes.light_ratio``):
Σ light × colour over Σ colour across the pixel filter's whole footprint, so a pixel whose own
sub-pixel rays missed a coloured surface that lies in its filter's tails still gets that
surface's light — a diffuse wall beside a metal floor has no dark outline in Diffuse Direct."""
import numpy as np
import pytest

from voxgi.voxgi_addon.preview.passes import light_ratio, neighbour_weights


def wall_beside_metal(wall_columns=4, width=8, height=3, light=2.0, colour=0.7):
    """A diffuse wall (colour, light) filling the left columns of the image, a metal floor
    (no diffuse colour, no diffuse light) the rest: light × colour and colour per pixel."""
    c = np.zeros((height, width, 3))
    c[:, :wall_columns] = colour
    return c * light, c


def test_a_pixel_beside_a_wall_takes_the_walls_light_as_cycles_does():
    lit, colour = wall_beside_metal()
    out = light_ratio(lit, colour, 1.5)
    assert np.allclose(out[:, :4], 2.0)          # the wall itself: unchanged
    assert np.allclose(out[:, 4], 2.0)           # its neighbour: the wall is in its footprint
    assert np.all(out[:, 5:] == 0.0)             # beyond the filter's reach: no light


def test_point_sampling_keeps_pixels_to_themselves():
    lit, colour = wall_beside_metal()
    assert np.all(light_ratio(lit, colour, 0.0)[:, 4:] == 0.0)
    assert np.all(light_ratio(lit, colour, 0.5)[:, 4:] == 0.0)


def test_a_sliver_in_a_neighbour_does_not_spread():
    """A neighbour holding only a sliver of the wall (a tenth of the wall's colour) may have it
    on its far side, outside the pixel's footprint: no light is borrowed from it."""
    lit, colour = wall_beside_metal()
    colour[:, 4] = 0.07
    lit[:, 4] = 0.07 * 2.0
    out = light_ratio(lit, colour, 1.5)
    assert np.allclose(out[:, 4], 2.0)
    assert np.all(out[:, 5] == 0.0)


def test_pixels_with_colour_keep_their_own_light():
    """Neighbours' light only decides pixels with no colour of their own: a shadow edge on one
    surface stays exactly as the pixels' own rays drew it."""
    rng = np.random.default_rng(3)
    colour = rng.uniform(0.2, 0.9, (6, 6, 3))
    light = rng.uniform(0.0, 5.0, (6, 6, 3))
    assert np.allclose(light_ratio(light * colour, colour, 1.5), light)


def test_the_background_stays_black():
    """A pixel whose rays all saw the background is 0 in every pass, beside a wall or not."""
    lit, colour = wall_beside_metal()
    covered = np.ones(colour.shape[:2], bool)
    covered[:, 4:] = False
    assert np.all(light_ratio(lit, colour, 1.5, covered)[:, 4:] == 0.0)


@pytest.mark.parametrize("size", [1.0, 1.5, 3.0])
def test_the_neighbours_share_is_the_filters(size):
    weights = neighbour_weights(size)
    assert weights[1, 1] == 1.0
    assert np.allclose(weights, weights.T) and np.allclose(weights, weights[::-1, ::-1])
    assert 0.0 < weights[1, 0] < 1.0 and np.isclose(weights[0, 0], weights[1, 0] ** 2)
    if size == 1.5:  # 11.9% of Cycles' 1.5 px Blackman-Harris beyond half a pixel on each side
        assert weights[1, 0] == pytest.approx(0.1555, abs=2e-3)

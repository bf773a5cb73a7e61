"""3D Morton codes: exact round trip, bit layout, parent/octant relations."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from voxgi.voxgi_addon.gi.morton import MAX_COORD, morton_decode, morton_encode


@settings(max_examples=100, deadline=None)
@given(arrays(np.int64, st.tuples(st.integers(0, 64), st.just(3)),
              elements=st.integers(0, MAX_COORD)))
def test_round_trip_is_exact(coords):
    keys = morton_encode(coords)
    assert keys.dtype == np.uint64 and keys.shape == (len(coords),)
    assert np.array_equal(morton_decode(keys), coords)


def test_bit_layout_x_then_y_then_z():
    coords = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [2, 0, 0], [0, 0, 2],
                       [MAX_COORD, MAX_COORD, MAX_COORD]])
    keys = morton_encode(coords)
    assert keys[:6].tolist() == [1, 2, 4, 7, 8, 32]
    assert int(keys[6]) == (1 << 63) - 1  # 63 bits used, bit 63 free
    assert np.array_equal(morton_decode(keys), coords)


def test_brute_force_interleave_on_random_coordinates():
    rng = np.random.default_rng(3)
    coords = rng.integers(0, MAX_COORD + 1, size=(200, 3))
    expected = [sum(((int(c[a]) >> b) & 1) << (3 * b + a) for b in range(21) for a in range(3))
                for c in coords]
    assert morton_encode(coords).tolist() == expected


def test_parent_is_shift_by_three_and_octant_is_low_bits():
    rng = np.random.default_rng(4)
    coords = rng.integers(0, 1 << 20, size=(5000, 3))
    keys = morton_encode(coords)
    assert np.array_equal(keys >> np.uint64(3), morton_encode(coords >> 1))
    octant = (coords[:, 2] & 1) << 2 | (coords[:, 1] & 1) << 1 | (coords[:, 0] & 1)
    assert np.array_equal(keys & np.uint64(7), octant.astype(np.uint64))


def test_out_of_range_is_refused():
    with pytest.raises(ValueError, match="2\\^21"):
        morton_encode(np.array([[MAX_COORD + 1, 0, 0]]))
    with pytest.raises(ValueError, match="2\\^21"):
        morton_encode(np.array([[0, -1, 0]]))
    assert morton_encode(np.zeros((0, 3), np.int64)).shape == (0,)

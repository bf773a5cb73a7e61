"""Packed voxel words round-trip within their stated precision."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from voxgi.voxgi_addon.voxelize import packing as vp


def test_positions_round_trip_exactly_with_flag():
    rng = np.random.default_rng(1)
    cells = rng.integers(0, 1024, size=(5000, 3))
    flags = rng.integers(0, 4, size=5000)
    back, back_flags = vp.unpack_positions(vp.pack_positions(cells, flags))
    assert (back == cells).all() and (back_flags == flags).all()
    assert vp.pack_positions(np.array([[1023, 1023, 1023]]), 3)[0] == 0xFFFFFFFF


def test_positions_out_of_10_bits_are_refused():
    import pytest
    with pytest.raises(ValueError, match="10-bit"):
        vp.pack_positions(np.array([[1024, 0, 0]]))


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (64, 3), elements=st.floats(-1, 1)))
def test_normals_within_snorm8_precision(raw):
    length = np.linalg.norm(raw, axis=1, keepdims=True)
    n = np.where(length > 1e-3, raw / np.maximum(length, 1e-3), [0, 0, 1])
    back = vp.unpack_normals(vp.pack_normals(n))
    assert np.abs(back - n).max() <= 0.5 / 127 + 1e-6


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (64, 4), elements=st.floats(0, 1)))
def test_colours_within_one_255th(rgba):
    back = vp.unpack_unorm8x4(vp.pack_unorm8x4(rgba))
    assert np.abs(back - rgba).max() <= 1 / 255


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (32, 4), elements=st.floats(0, 1)))
def test_weights_stay_normalised_and_close(w):
    q = vp.quantize_weights(w)
    total = w.sum(axis=1)
    assert (q.astype(int).sum(axis=1) == np.where(total > 0, 255, 0)).all()
    back = vp.unpack_weights(vp.pack_weights(w))
    expected = np.divide(w, total[:, None], out=np.zeros_like(w), where=total[:, None] > 0)
    assert np.abs(back - expected).max() <= 1 / 255 + 1e-6


def test_bone_indices_round_trip():
    idx = np.array([[0, 1, 2, 255], [7, 7, 0, 3]])
    assert (vp.unpack_indices(vp.pack_indices(idx)) == idx).all()


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (64, 3), elements=st.floats(-1, 1)),
       arrays(np.float64, (64,), elements=st.floats(-1, 1)))
def test_plane_offsets_round_trip_within_one_127th_of_their_range(raw, frac):
    """The top byte of the normal word: the plane offset in voxel spans, SNORM8 over the
    quantised normal's reach ½|n|₁ (the farthest a plane with that normal still cuts the
    voxel); unpacking it leaves the normal untouched."""
    length = np.linalg.norm(raw, axis=1, keepdims=True)
    n = np.where(length > 1e-3, raw / np.maximum(length, 1e-3), [0, 0, 1])
    reach = vp.plane_reach(vp.unpack_normals(vp.pack_normals(n)))
    offsets = frac * reach
    words = vp.pack_normals(n, offsets)
    back = vp.unpack_plane_offsets(words)
    assert back.dtype == np.float32
    assert np.abs(back - offsets).max() <= reach.max() / 127
    np.testing.assert_array_equal(vp.unpack_normals(words), vp.unpack_normals(vp.pack_normals(n)))


def test_plane_offset_range_and_the_no_plane_code():
    n = np.array([[1, 0, 0], [0, -1, 0], [1, 1, 1], [1, 1, 1], [0, 0, 1]]) / np.sqrt([[1], [1], [3], [3], [1]])
    reach = vp.plane_reach(n)
    np.testing.assert_allclose(reach, [0.5, 0.5, np.sqrt(3) / 2, np.sqrt(3) / 2, 0.5])
    words = vp.pack_normals(n, [0.25, 9.0, -9.0, np.nan, 0.0])  # beyond the reach: clamped
    back = vp.unpack_plane_offsets(words)
    np.testing.assert_allclose(back[:3], [0.25, 0.5, -np.sqrt(3) / 2], atol=0.5 * 0.5 / 127)
    assert np.isnan(back[3]) and back[4] == 0 and (words[3] >> 24) == 0x80  # code -128
    assert (vp.pack_normals(n) >> 24 == 0).all()  # no offsets given: the plane through the centre

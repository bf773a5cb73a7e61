"""The sparse gather's rays per traced point (``preview.sparse_gather.sparse_settings``): the
cells left out lend their rays to the traced ones, and only those — so a scene whose cells are
nearly all traced (a bumpy terrain of sub-pixel triangles fails the same-surface test
everywhere) never traces more rays than a dense gather would."""
from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from voxgi.voxgi_addon.preview.gather import GatherSettings
from voxgi.voxgi_addon.preview.sparse_gather import SPARSE_RAYS, sparse_settings


def test_a_quarter_traced_draws_the_full_share():
    """A smooth room (a quarter of its cells traced) keeps SPARSE_RAYS × the rays a point."""
    settings = GatherSettings(rays=64, sparse=True)
    assert sparse_settings(settings).rays == round(64 * SPARSE_RAYS)
    assert sparse_settings(settings, 15600, 4369).rays == round(64 * SPARSE_RAYS)


def test_nearly_every_cell_traced_draws_no_more_than_a_dense_gather():
    """87% of the cells traced (the glTF diorama's terrain): 73 rays a point, not 96."""
    settings = GatherSettings(rays=64, sparse=True)
    rays = sparse_settings(settings, 12744, 11125).rays
    assert rays == 73
    assert rays * 11125 <= 64 * 12744 * 1.001


@given(valid=st.integers(1, 100_000), share=st.floats(0.01, 1.0), rays=st.integers(1, 512))
def test_the_first_list_never_traces_more_than_a_dense_gather(valid, share, rays):
    traced = max(1, int(valid * share))
    per_point = sparse_settings(GatherSettings(rays=rays, sparse=True), valid, traced).rays
    assert 1 <= per_point <= round(rays * SPARSE_RAYS)
    # rounding aside (half a ray a point), the traced points draw at most the dense rays
    assert per_point * traced <= (rays + 0.5) * valid
    assert per_point >= min(rays, round(rays * SPARSE_RAYS))  # never fewer than a dense point

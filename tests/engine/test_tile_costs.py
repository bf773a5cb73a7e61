"""Where a view's slices cost their time (voxgi_addon/preview/tile_costs.py): the cost map
predicts a stage over a tile from where the tile lies, and a tile that would run a stage past
its budget is cut into tiles of every tile's kind that cover it exactly once."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voxgi.voxgi_addon.preview.progressive import allowed_side
from voxgi.voxgi_addon.preview.tile_costs import CostMap, split_tile, split_to_fit


def covered(rects, width, height):
    """How many times each pixel of a width × height image lies in the rects (clipped)."""
    count = np.zeros((height, width), int)
    for x0, y0, w, h in rects:
        count[max(y0, 0):max(y0 + h, 0), max(x0, 0):max(x0 + w, 0)] += 1
    return count


def panel_map(width=160, height=120):
    """A stage that costs 10 µs a pixel over the image's right half and 1 µs elsewhere, as
    tiles of 40 × 40 measured it."""
    costs = CostMap(width, height)
    for y0 in range(0, height, 40):
        for x0 in range(0, width, 40):
            per_pixel = 10e-6 if x0 >= width // 2 else 1e-6
            costs.measured(("tile", 3), (x0, y0, 40, 40), per_pixel * 1600)
    return costs


def test_a_stage_is_predicted_from_where_the_tile_lies():
    costs = panel_map()
    cheap = costs.predicted(("tile", 3), (0, 0, 48, 40))
    dear = costs.predicted(("tile", 3), (96, 40, 48, 40))
    assert cheap == pytest.approx(1e-6 * 48 * 40)
    assert dear == pytest.approx(10e-6 * 48 * 40)
    # a tile across the edge: its cells' mean
    across = costs.predicted(("tile", 3), (56, 0, 48, 40))
    assert cheap < across < dear
    assert costs.predicted(("tile", 4), (0, 0, 48, 40)) is None  # a stage never run
    assert costs.predicted(("tile", 3), (200, 0, 48, 40)) is None  # past the image
    assert costs.longest("tile", (96, 40, 48, 40)) == pytest.approx(dear)
    assert costs.longest("lit tile", (96, 40, 48, 40)) is None
    # a stage not yet run over part of a tile: no prediction from the map
    partial = CostMap(160, 120)
    partial.measured(("tile", 0), (0, 0, 40, 40), 0.004)
    assert partial.predicted(("tile", 0), (0, 0, 80, 40)) is None
    # the last tile over a cell is what it costs
    partial.measured(("tile", 0), (0, 0, 40, 40), 0.008)
    assert partial.predicted(("tile", 0), (0, 0, 40, 40)) == pytest.approx(0.008)


def test_bad_measurements_are_not_kept_and_a_bad_map_is_refused():
    costs = CostMap(64, 48)
    costs.measured(("tile", 0), (0, 0, 24, 24), float("nan"))
    costs.measured(("tile", 0), (0, 0, 24, 24), -1.0)
    costs.measured(("tile", 0), (0, 0, 0, 24), 0.01)
    assert costs.predicted(("tile", 0), (0, 0, 24, 24)) is None
    with pytest.raises(ValueError, match="cost map"):
        CostMap(0, 48)


def test_a_tile_is_cut_across_its_longer_side_into_sides_of_every_tiles_kind():
    # 48 × 40 at 8-pixel work groups: 48 = 24 + 24; 40 (five groups) has no such cut
    assert split_tile((8, 16, 48, 40), 8, 1) == ((8, 16, 24, 40), (32, 16, 24, 40))
    assert split_tile((8, 16, 40, 48), 8, 1) == ((8, 16, 40, 24), (8, 40, 40, 24))
    # 56 (seven groups: 3 + 4 or 5 + 2 would make a power of two) is cut across the other side
    assert split_tile((0, 0, 56, 48), 8, 1) == ((0, 0, 56, 24), (0, 24, 56, 24))
    assert split_tile((0, 0, 24, 40), 8, 1) is None  # nothing left to cut
    # at a gather stride of 3: sides of 24-pixel groups, no power of two in cells either
    parts = split_tile((0, 0, 144, 72), 24, 3)
    assert parts == ((0, 0, 72, 72), (72, 0, 72, 72))


def test_a_costly_tile_is_cut_until_each_part_fits_and_the_parts_cover_it_once():
    costs = panel_map()
    budget = 0.006
    cheap = (0, 0, 48, 40)
    assert split_to_fit(cheap, lambda r: costs.longest("tile", r), budget, 8, 1,
                        costs.inside) == [cheap]
    dear = (96, 40, 48, 40)  # 19 ms predicted
    parts = split_to_fit(dear, lambda r: costs.longest("tile", r), budget, 8, 1, costs.inside)
    assert len(parts) == 2  # 48 = 24 + 24, then 24 × 40 cannot be cut again
    assert all(costs.longest("tile", p) < 1.1 * costs.longest("tile", dear) / 2 for p in parts)
    assert (covered(parts, 160, 120) == covered([dear], 160, 120)).all()
    # a bigger tile is cut more than once; parts past the image's border are dropped
    big = (120, 72, 72, 72)
    parts = split_to_fit(big, lambda r: costs.longest("tile", r), budget, 8, 1, costs.inside)
    assert len(parts) > 2
    assert all(costs.inside(p) for p in parts)
    inside_big = np.minimum(covered([big], 160, 120), 1)
    assert (covered(parts, 160, 120) == inside_big).all()
    # unknown costs: the tile stays whole
    assert split_to_fit(big, lambda r: None, budget, 8, 1, costs.inside) == [big]


@settings(max_examples=60, deadline=None)
@given(groups=st.tuples(st.integers(3, 20), st.integers(3, 20)),
       origin=st.tuples(st.integers(-40, 150), st.integers(-40, 110)),
       budget=st.floats(1e-4, 0.05), stride=st.sampled_from([1, 3]),
       seed=st.integers(0, 1000))
def test_cut_tiles_keep_every_tiles_kind_and_cover_the_tile_once(groups, origin, budget,
                                                                  stride, seed):
    multiple = 8 * stride
    w, h = groups[0] * multiple, groups[1] * multiple
    if not (allowed_side(w, stride) and allowed_side(h, stride)):
        return  # not a tile of the view's kind
    rng = np.random.default_rng(seed)
    costs = CostMap(160, 120)
    for y0 in range(0, 120, 24):
        for x0 in range(0, 160, 24):
            costs.measured(("tile", 0), (x0, y0, 24, 24), float(rng.uniform(0.0, 0.01)))
    rect = (*origin, w, h)
    parts = split_to_fit(rect, lambda r: costs.longest("tile", r), budget, multiple, stride,
                         costs.inside)
    for x0, y0, pw, ph in parts:
        assert allowed_side(pw, stride) and allowed_side(ph, stride)
        assert pw % multiple == 0 and ph % multiple == 0
    inside = np.minimum(covered([rect], 160, 120), 1)
    if costs.inside(rect):
        assert (covered(parts, 160, 120) == inside).all()

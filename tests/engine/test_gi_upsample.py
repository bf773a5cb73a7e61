"""Reduced-resolution diffuse/AO tracing: which pixels are traced and how the rest are filled."""
import numpy as np
import pytest

from voxgi.voxgi_addon.preview.upsample import (
    EmitterField,
    sample_pixels,
    upsample,
    upsample_at,
)


def two_walls(height=24, width=32):
    """A floor (z = 0, normal +z) on the left half and a wall (x = 1, normal −x) on the right,
    seen head-on: G-buffer position/normal per pixel, and a value that varies smoothly."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    left = xs < width // 2
    position = np.where(left[..., None], np.stack([xs / width, ys / height, 0 * xs], -1),
                        np.stack([1 + 0 * xs, ys / height, xs / width], -1)).astype(np.float32)
    normal = np.where(left[..., None], np.array([0, 0, 1], np.float32),
                      np.array([-1, 0, 0], np.float32))
    value = np.where(left, 0.2 + 0.01 * xs, 2.0 + 0.02 * ys)[..., None].astype(np.float32)
    return position, normal, value


def test_stride_one_is_the_identity_and_background_stays_zero():
    position, normal, value = two_walls()
    hit = np.ones(value.shape[:2], bool)
    hit[0, :] = False
    out = upsample(value, hit, hit, position, normal, 1)
    assert np.array_equal(out[hit], value[hit]) and (out[~hit] == 0).all()


@pytest.mark.parametrize("stride", [2, 4])
def test_upsampling_keeps_surfaces_apart_and_reproduces_traced_pixels(stride):
    position, normal, value = two_walls()
    height, width = value.shape[:2]
    hit = np.ones((height, width), bool)
    rows, cols = sample_pixels(height, width, stride)
    assert rows.tolist() == list(range(stride // 2, height, stride))
    low = value[rows][:, cols]
    out = upsample(low, hit[rows][:, cols], hit, position, normal, stride)
    # Traced pixels keep their value: the B-spline reproduces the ramps inside each surface;
    # at image borders and where the other surface's cells drop out, nearly.
    inner = out[rows][:, cols][1:-1, 1:len(cols) // 2 - 1]
    np.testing.assert_allclose(inner, low[1:-1, 1:len(cols) // 2 - 1], rtol=1e-5)
    assert np.abs(out[rows][:, cols] - low).max() < 0.005 * stride + 1e-6
    # No floor value leaks onto the wall or back.
    left = np.arange(width) < width // 2
    assert out[:, left].max() < 1.0 and out[:, ~left].min() > 1.0
    # Smooth values come back within what the block size allows.
    assert np.abs(out - value).max() < 0.02 * stride + 1e-6


def test_pixels_without_a_traced_neighbour_on_their_surface_take_the_nearest():
    position, normal, value = two_walls()
    height, width = value.shape[:2]
    hit = np.ones((height, width), bool)
    rows, cols = sample_pixels(height, width, 4)
    valid = np.zeros((len(rows), len(cols)), bool)
    valid[0, 0] = True  # a single traced cell
    out = upsample(value[rows][:, cols], valid, hit, position, normal, 4)
    assert np.allclose(out[:6, :6], value[rows[0], cols[0]])  # filled, not black


def test_auto_stride_keeps_the_traced_points_near_160_by_120():
    from voxgi.voxgi_addon.preview.upsample import AUTO_POINTS, auto_stride, low_shape

    assert auto_stride(160, 120) == 1
    assert auto_stride(320, 240) == 2
    assert auto_stride(640, 480) == 3
    assert auto_stride(800, 600) == 4
    assert auto_stride(4000, 3000) == 4  # Quarter is the coarsest
    for w, h in ((200, 150), (481, 361), (1920, 1080)):
        stride = auto_stride(w, h)
        hl, wl = low_shape(h, w, stride)
        assert hl * wl <= AUTO_POINTS or stride == 4


@pytest.mark.parametrize("stride", [2, 3, 4])
def test_cell_noise_does_not_show_the_grid_of_traced_pixels(stride):
    """The traced cells keep some noise after denoising. Bilinear upsampling showed it at full
    strength on the traced pixels and averaged it between them: a grid of dots one block
    apart on every flat wall at Half and Quarter GI resolution. The B-spline averages
    everywhere, so the noise left is alike at every pixel of a block."""
    height, width = 64 * stride, 64 * stride
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    position = np.stack([xs, ys, 0 * xs], -1) / width
    normal = np.broadcast_to(np.array([0, 0, 1], np.float32), position.shape)
    hit = np.ones((height, width), bool)
    rows, cols = sample_pixels(height, width, stride)
    noise = np.random.default_rng(1).normal(size=(len(rows), len(cols), 1)).astype(np.float32)
    out = upsample(noise, np.ones(noise.shape[:2], bool), hit, position, normal, stride)[..., 0]
    inner = out[stride:-stride, stride:-stride]
    phase = inner.reshape(-1, stride, inner.shape[1] // stride, stride).var(axis=(0, 2))
    assert phase.min() > 0.6 * phase.max(), phase  # bilinear: 0.25 at stride 2


def test_the_emitters_field_reproduces_a_linear_light_and_tells_where_it_turns():
    """``EmitterField`` (the GLSL's UPSAMPLE_FIELD): on a floor seen head-on, a light linear in
    position comes back exact at every pixel and at sub-pixel samples; the turn is the taps' steps
    over the distance left to the emitters (1-Lipschitz), so it grows as they come near, and
    is −1 where no tap lies on the point's surface."""
    height, width, stride = 24, 32, 4
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    position = np.stack([xs * 0.01, ys * 0.01, 0 * xs], -1).astype(np.float32)
    normal = np.broadcast_to(np.array([0, 0, 1], np.float32), position.shape).copy()
    rows, cols = sample_pixels(height, width, stride)
    cells = position[rows][:, cols]
    light = (1.0 + cells[..., :1] + 2.0 * cells[..., 1:2]) * np.ones(3, np.float32)
    valid = np.ones((len(rows), len(cols)), bool)

    def field(distance):
        return EmitterField(light, light, np.full(valid.shape, distance), valid, position, normal,
                            stride, np.array([0.16, 0.12, 5.0]))

    far, near = field(10.0), field(0.1)
    # away from the image's border, where the taps surround the point
    inner = (ys >= stride) & (ys < height - stride) & (xs >= stride) & (xs < width - stride)
    pick = np.flatnonzero(inner.ravel())
    expected = 1.0 + position.reshape(-1, 3)[pick, 0] + 2.0 * position.reshape(-1, 3)[pick, 1]
    glossy, glossy_turn, diffuse, turn = far.at_centres(pick)
    assert np.allclose(diffuse[:, 0], expected, atol=1e-5)
    assert np.allclose(glossy[:, 0], expected, atol=1e-5)
    r, c = np.divmod(pick, width)
    moved = position.reshape(-1, 3)[pick] + np.array([0.003, 0.002, 0.0], np.float32)
    _, _, at, _ = far.at(r, c, moved, normal.reshape(-1, 3)[pick], offset=(0.3, 0.2))
    assert np.allclose(at[:, 0], 1.0 + moved[:, 0] + 2.0 * moved[:, 1], atol=1e-5)
    assert (turn > 0).all() and (glossy_turn > turn).all() and (turn < 0.01).all()
    assert (near.at_centres(pick)[3] > 10 * turn).all()
    # a point on a wall across the floor's taps: none on its surface
    wall = np.array([[0.0, 1.0, 0.0]] * len(pick), np.float32)
    assert (far.at(r, c, position.reshape(-1, 3)[pick], wall)[3] == -1).all()
    # at stride 1 every pixel reads its own gather point, turn 0
    own = EmitterField(position, position, np.ones((height, width)), np.ones((height, width), bool),
                       position, normal, 1, None).at_centres(pick)
    assert np.array_equal(own[2], position.reshape(-1, 3)[pick]) and not own[3].any()


@pytest.mark.parametrize("stride", [1, 2])
def test_a_sub_pixel_sample_reads_the_gathers_of_the_surface_it_sees(stride):
    """``upsample_at`` (the GLSL's UPSAMPLE_TERMS): a sample of a pixel on the floor's side of
    the crease that sees the wall (half a pixel right) takes the wall's gathered value, not the
    floor's; a point on neither surface fits no gather point (its centre's value is kept)."""
    position, normal, value = two_walls()
    height, width = value.shape[:2]
    hit = np.ones((height, width), bool)
    rows, cols = sample_pixels(height, width, stride)
    low = [value[rows][:, cols], 2.0 * value[rows][:, cols]]
    valid = hit[rows][:, cols]
    row, col = np.array([11, 11]), np.array([width // 2 - 1, width // 2 - 1])
    wall = np.array([[1.0, row[0] / height, (col[0] + 0.5) / width],   # the wall, seen
                     [0.5, 0.5, 0.5]], np.float32)                     # in the air
    normals = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.float32)
    (first, second), fits = upsample_at(low, valid, position, normal, stride, row, col, wall,
                                        normals, (0.5, 0.0))
    assert fits.tolist() == [True, False]
    assert abs(first[0, 0] - (2.0 + 0.02 * row[0])) < 0.02  # the wall's, not the floor's 0.35
    assert np.allclose(second[0], 2.0 * first[0]) and (first[1] == 0).all()

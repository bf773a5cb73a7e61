"""Direct diffuse light in Cycles' units (irradiance / π) against closed forms and brute force.

The closed forms are those measured against Cycles in docs/blender_facts.md "Cycles' radiometry".
"""
import math

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.direct_light import concentric_disk, diffuse_direct, stratified_square
from voxgi.voxgi_addon.scene.geometry import SceneTriangles
from voxgi.voxgi_addon.scene.snapshot import LightData

WHITE = np.ones(3, np.float32)


def frame(position, rotation=None):
    m = np.eye(4)
    if rotation is not None:
        m[:3, :3] = rotation
    m[:3, 3] = position
    return m


def rot_x(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def floor_points(n=9, extent=2.0):
    """Points of the z = 0 plane on an n × n grid and their +Z normals."""
    c = np.linspace(-extent, extent, n)
    x, y = np.meshgrid(c, c)
    p = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    return p, np.tile([0.0, 0.0, 1.0], (len(p), 1))


def quad_soup(corners):
    """SceneTriangles of quads given as (Q, 4, 3) corners."""
    c = np.asarray(corners, dtype=np.float64)
    tri = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    zeros = np.zeros(len(tri), np.int32)
    return SceneTriangles(tri, n, zeros, zeros)


def rectangle_factor(x0, x1, y0, y1, h):
    """∫ cosθ_x cosθ_l / (π r²) dA of the rectangle [x0, x1]×[y0, y1] at height h above a point at the
    origin (the configuration factor, by superposition of corner rectangles)."""
    def corner(a, b):
        sa, sb = np.sign(a), np.sign(b)
        a, b = np.abs(a) / h, np.abs(b) / h
        f = (a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a))
             + b / np.sqrt(1 + b * b) * np.arctan(a / np.sqrt(1 + b * b))) / (2 * math.pi)
        return sa * sb * f
    return corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0)


def test_point_light_matches_the_inverse_square_cosine_law():
    p, n = floor_points()
    light = LightData("p", "POINT", WHITE, 100.0, frame((0.3, -0.2, 2.0)))
    got = diffuse_direct(p, n, [light], None)
    d = np.array([0.3, -0.2, 2.0]) - p
    d2 = (d * d).sum(1)
    expected = 100.0 / (4 * math.pi * d2) / math.pi * d[:, 2] / np.sqrt(d2)
    np.testing.assert_allclose(got[:, 0], expected, rtol=1e-5)
    assert got.dtype == np.float32 and got.shape == (len(p), 3)
    # docs/blender_facts.md: 100 W at 2 m straight above reads 0.6333 (Cycles measured 0.6317)
    above = diffuse_direct([[0.3, -0.2, 0.0]], [[0, 0, 1.0]], [light], None)[0, 0]
    assert above == pytest.approx(0.6333, abs=1e-4)


def test_point_light_radius_uses_cycles_soft_falloff():
    p, n = floor_points()
    light = LightData("p", "POINT", WHITE, 100.0, frame((0, 0, 1.0)), radius=0.5)
    got = diffuse_direct(p, n, [light], quad_soup([[(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]]))
    d2 = (p * p).sum(1) + 1.0
    expected = 100.0 / (4 * math.pi) / (d2 + 0.25) / math.pi / np.sqrt(d2)
    np.testing.assert_allclose(got[:, 0], expected, rtol=1e-5)  # the floor does not shadow itself


def test_sun_is_strength_over_pi_times_cosine_and_coloured():
    p, n = floor_points(5)
    tilt = math.radians(35)
    color = np.array([1.0, 0.5, 0.25], np.float32)
    sun = LightData("s", "SUN", color, 3.0, frame((0, 0, 10), rot_x(tilt)), angle=math.radians(5))
    got = diffuse_direct(p, n, [sun], quad_soup([[(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]]))
    np.testing.assert_allclose(got, np.tile(3.0 / math.pi * math.cos(tilt) * color, (len(p), 1)), rtol=1e-5)
    # a sun below the horizon gives nothing
    under = LightData("s", "SUN", WHITE, 3.0, frame((0, 0, 0), rot_x(math.pi)))
    assert not diffuse_direct(p, n, [under], None).any()


def test_spot_cone_and_blend_follow_cycles():
    size, blend, h = math.radians(90), 0.5, 1.0
    spot = LightData("s", "SPOT", WHITE, 100.0, frame((0, 0, h)), spot_size=size, spot_blend=blend)
    point = LightData("p", "POINT", WHITE, 100.0, frame((0, 0, h)))
    angles = np.radians([0, 20, 30, 40, 44, 46, 60])
    p = np.stack([h * np.tan(angles), np.zeros(7), np.zeros(7)], axis=1)
    n = np.tile([0, 0, 1.0], (7, 1))
    ratio = diffuse_direct(p, n, [spot], None)[:, 0] / diffuse_direct(p, n, [point], None)[:, 0]
    cos_half = math.cos(size / 2)
    x = np.clip((np.cos(angles) - cos_half) / ((1 - cos_half) * blend), 0, 1)
    np.testing.assert_allclose(ratio, x * x * (3 - 2 * x), atol=1e-6)
    assert ratio[0] == pytest.approx(1.0) and ratio[-1] == 0.0 and 0 < ratio[4] < 0.1
    hard = LightData("s", "SPOT", WHITE, 100.0, frame((0, 0, h)), spot_size=size, spot_blend=0.0)
    hard_ratio = diffuse_direct(p, n, [hard], None)[:, 0] / diffuse_direct(p, n, [point], None)[:, 0]
    np.testing.assert_allclose(hard_ratio, (angles < size / 2).astype(float), atol=1e-6)


@pytest.mark.parametrize("shape,sx,sy", [("SQUARE", 1.0, 1.0), ("RECTANGLE", 1.5, 0.5)])
def test_area_light_over_a_plane_is_exact(shape, sx, sy):
    p, n = floor_points(11)
    light = LightData("a", "AREA", WHITE, 100.0, frame((0, 0, 1.0)), size=sx, size_y=sy, shape=shape)
    got = diffuse_direct(p, n, [light], None)[:, 0]
    radiance = 100.0 / (math.pi * sx * sy)  # P / (π A): a cosine emitter of power P
    x, y = p[:, 0], p[:, 1]
    expected = radiance * rectangle_factor(-sx / 2 - x, sx / 2 - x, -sy / 2 - y, sy / 2 - y, 1.0)
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    # docs/blender_facts.md's small-square limit P / (π d²) / π
    tiny = LightData("a", "AREA", WHITE, 100.0, frame((0, 0, 2.0)), size=0.01, shape="SQUARE")
    below = diffuse_direct([[0, 0, 0.0]], [[0, 0, 1.0]], [tiny], None)[0, 0]
    assert below == pytest.approx(100.0 / (math.pi * 4.0) / math.pi, rel=1e-4)


def test_disk_and_ellipse_lights():
    r, h = 0.5, 1.0
    disk = LightData("d", "AREA", WHITE, 100.0, frame((0, 0, h)), size=2 * r, shape="DISK")
    on_axis = diffuse_direct([[0, 0, 0.0]], [[0, 0, 1.0]], [disk], None)[0, 0]
    expected = 100.0 / (math.pi * math.pi * r * r) * r * r / (r * r + h * h)  # L · sin²α
    assert on_axis == pytest.approx(expected, rel=2e-3)
    ellipse = LightData("e", "AREA", WHITE, 100.0, frame((0, 0, h)), size=2 * r, size_y=2 * r, shape="ELLIPSE")
    p, n = floor_points(5)
    np.testing.assert_allclose(diffuse_direct(p, n, [ellipse], None), diffuse_direct(p, n, [disk], None))


def test_area_light_is_one_sided_and_handles_the_horizon():
    light = LightData("a", "AREA", WHITE, 50.0, frame((0, 0, 1.0), rot_x(math.radians(60))),
                      size=1.0, size_y=0.5, shape="RECTANGLE")
    assert diffuse_direct([[0, 0, 2.0]], [[0, 0, -1.0]], [light], None)[0, 0] == 0  # behind it
    # Points whose horizon cuts the light: exact (the light clipped by the horizon), with no
    # noise whatever the samples or seed, against a dense quadrature
    p = np.array([[0.0, 0.0, 1.05], [0.2, 1.0, 1.1], [0.0, 0.6, 1.0]])
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.8, 0.0, 0.6]])
    got = diffuse_direct(p, n, [light], None, samples=1)[:, 0]
    for samples, seed in ((16, 0), (16, 7), (4, 3)):
        np.testing.assert_allclose(diffuse_direct(p, n, [light], None, samples=samples,
                                                  seed=seed)[:, 0], got, rtol=1e-12)
    u, v = np.meshgrid((np.arange(400) + 0.5) / 400 - 0.5, (np.arange(200) + 0.5) / 200 - 0.5)
    m = light.world_matrix
    y = m[:3, 3] + u.reshape(-1, 1) * m[:3, 0] * 1.0 + v.reshape(-1, 1) * m[:3, 1] * 0.5
    emit = -m[:3, 2]
    radiance = 50.0 / (math.pi * 0.5)
    for i in range(3):
        w = y - p[i]
        r2 = (w * w).sum(1)
        f = np.maximum(w @ n[i], 0) * np.maximum(-(w @ emit), 0) / r2**2
        assert got[i] == pytest.approx(radiance * f.mean() * 0.5 / math.pi, rel=2e-3)
    assert got[0] == 0.0 and got[1:].min() > 0.0  # the first behind the one-sided light


def test_hard_shadows_and_soft_shadows_against_brute_force():
    p, n = floor_points(8, 1.0)  # no point at x = 0, where the shadow edge falls
    blocker = quad_soup([[(-3, -3, 1.0), (0, -3, 1.0), (0, 3, 1.0), (-3, 3, 1.0)]])  # covers x < 0
    point = LightData("p", "POINT", WHITE, 100.0, frame((0.0, 0.0, 2.0)))
    lit = diffuse_direct(p, n, [point], blocker)[:, 0]
    free = diffuse_direct(p, n, [point], None)[:, 0]
    # the ray to (0, 0, 2) crosses z = 1 at x/2: blocked exactly where x < 0
    np.testing.assert_array_equal(lit == 0, p[:, 0] < 0)
    np.testing.assert_allclose(lit[p[:, 0] > 0], free[p[:, 0] > 0], rtol=1e-6)

    area = LightData("a", "AREA", WHITE, 100.0, frame((0, 0, 2.0)), size=1.0, shape="SQUARE")
    soft = diffuse_direct(p, n, [area], blocker, samples=256)[:, 0]
    # brute force: the blocker hides the light points whose ray crosses z = 1 at x < 0
    u = (np.arange(200) + 0.5) / 200 - 0.5
    lx, ly = np.meshgrid(u, u)
    light_points = np.stack([lx.ravel(), ly.ravel(), np.full(lx.size, 2.0)], axis=1)
    radiance = 100.0 / math.pi
    for i in range(len(p)):
        w = light_points - p[i]
        r2 = (w * w).sum(1)
        f = w[:, 2] ** 2 / r2**2
        visible = (p[i, 0] + w[:, 0] * (1.0 - p[i, 2]) / w[:, 2]) > 0
        expected = radiance * (f * visible).mean() / math.pi
        assert soft[i] == pytest.approx(expected, abs=0.02 * soft.max())


def test_custom_occluders_seed_and_linearity():
    class Everything:
        def __init__(self):
            self.calls = 0

        def occluded(self, origins, dirs, max_t):
            self.calls += 1
            return np.ones(len(origins), bool)

    p, n = floor_points(4)
    light = LightData("a", "AREA", WHITE, 10.0, frame((0, 0, 1.0)), size=0.5)
    blocker = Everything()
    assert not diffuse_direct(p, n, [light], blocker).any() and blocker.calls > 0
    a = diffuse_direct(p, n, [light, light], None, seed=3)
    np.testing.assert_allclose(a, 2 * diffuse_direct(p, n, [light], None, seed=3), rtol=1e-6)
    wall = quad_soup([[(0.1, -3, 0.01), (0.1, 3, 0.01), (0.1, 3, 3), (0.1, -3, 3)]])
    np.testing.assert_array_equal(diffuse_direct(p, n, [light], wall, seed=7),
                                  diffuse_direct(p, n, [light], wall, seed=7))


def test_sampling_patterns_are_stratified_and_on_the_disc():
    rng = np.random.default_rng(0)
    s = stratified_square(3, 16, rng)
    assert s.shape == (3, 16, 2)
    cells = np.floor(s * 4).astype(int)
    assert all(len({tuple(c) for c in cells[i]}) == 16 for i in range(3))  # one per stratum
    d = concentric_disk(s)
    assert (np.linalg.norm(d, axis=-1) <= 1 + 1e-12).all()
    many = concentric_disk(rng.random((200000, 2)))
    assert (np.linalg.norm(many, axis=1) < 0.5).mean() == pytest.approx(0.25, abs=0.005)  # uniform


def test_corners_that_agree_settle_a_lights_share():
    """At 4 × 4 strata the four corner strata are traced first; where those that count agree
    (a point that sees all of a light, or none of it) the other 12 are not traced and the
    share is theirs — the same as tracing all 16 there. Points in a penumbra trace all 16."""
    from voxgi.voxgi_addon.gi import direct_light

    class Counting:
        def __init__(self, inner):
            self.inner, self.rays = inner, 0

        def occluded(self, origins, dirs, max_t):
            self.rays += len(origins)
            return direct_light.raycast.occluded(self.inner, origins, dirs, max_t)

    p, n = floor_points(12, 1.5)
    blocker = quad_soup([[(-3, -3, 0.5), (0, -3, 0.5), (0, 3, 0.5), (-3, 3, 0.5)]])  # x < 0
    lights = [LightData("a", "AREA", WHITE, 50.0, frame((0, 0, 1.0)), size=0.6),
              LightData("p", "POINT", WHITE, 50.0, frame((0.3, 0.2, 1.2)), radius=0.2),
              LightData("s", "SUN", WHITE, 3.0, frame((0, 0, 5.0), rot_x(0.3)),
                        angle=math.radians(8.0))]
    for light in lights:
        counted = Counting(blocker)
        got = diffuse_direct(p, n, [light], counted, samples=16, seed=2)
        saved = direct_light.ADAPTIVE_FROM
        direct_light.ADAPTIVE_FROM = 99  # every stratum traced
        try:
            every = Counting(blocker)
            full = diffuse_direct(p, n, [light], every, samples=16, seed=2)
        finally:
            direct_light.ADAPTIVE_FROM = saved
        # the same wherever the corners disagree (all 16 traced) or all 16 agree; a point whose
        # corners agree but not all of its strata (the edge of a penumbra) may differ a little
        same = np.isclose(got[:, 0], full[:, 0], rtol=1e-12, atol=0.0)
        assert same.mean() > 0.8, light.type
        assert np.abs(got - full).max() <= 0.25 * full.max(), light.type
        assert full[:, 0].min() < 0.5 * full[:, 0].max(), light.type  # some shadow, some light
        assert counted.rays < 0.6 * every.rays, (light.type, counted.rays, every.rays)


def test_rectangle_points_are_uniform_in_their_solid_angle():
    """``sampling.spherical_rectangle`` (Ureña et al. 2013): its points lie on the rectangle,
    its solid angle is the area integral of cos θ_l / r², and the points' density over the
    area is that integrand over the solid angle (uniform in solid angle), from points in front,
    beside and nearly in the rectangle's plane."""
    from voxgi.voxgi_addon.gi.sampling import spherical_rectangle

    rng = np.random.default_rng(3)
    corner, ex, ey = np.array([-0.3, -0.2, 2.0]), np.array([0.6, 0.0, 0.0]), np.array([0, 0.4, 0])
    origins = np.array([[0.1, 0.0, 0.0], [1.5, 0.3, 1.2], [0.0, 0.1, 3.0], [0.2, 0.1, 1.98]])
    points, solid = spherical_rectangle(origins, corner, ex, ey, rng.random((4, 100_000, 2)))
    rel = points - corner
    assert np.abs(rel[..., 2]).max() < 1e-9
    assert rel[..., 0].min() > -1e-9 and rel[..., 0].max() < 0.6 + 1e-9
    assert rel[..., 1].min() > -1e-9 and rel[..., 1].max() < 0.4 + 1e-9
    area = rng.random((400_000, 2))
    on = corner + area[:, :1] * ex + area[:, 1:] * ey
    for o, points_o, solid_o in zip(origins, points, solid):
        w = on - o
        r2 = (w * w).sum(1)
        integrand = np.abs(w[:, 2]) / r2 ** 1.5
        assert solid_o == pytest.approx(integrand.mean() * 0.24, rel=0.01)
        # uniform in solid angle: E[1 / (its density per area)] over the points = the area
        w = points_o - o
        r2 = (w * w).sum(-1)
        inverse_density = solid_o * r2 ** 1.5 / np.abs(w[:, 2])
        assert inverse_density.mean() == pytest.approx(0.24, rel=0.02)


def test_a_penumbra_read_by_one_stratum_per_pass_keeps_its_light():
    """The anti-aliased preview's sixteen sub-pixel passes each draw one stratum of a light's
    4 × 4 (``strata_block``), so a pass's share of the light is one sample's visibility. Under
    a rectangular light half hidden by a wall their mean must stay within 6% of the light the
    whole stratified set finds with many rays: drawn by solid angle, a sample's visibility
    weighs what it should but for the cosine at the point (0.95–0.99 here). Drawn by area, as
    a disk still is, the passes read the unweighted visible area: 0.84–0.95 of it here, 12–20%
    dark in the Cornell box's penumbrae (docs/gi_pipeline.md "Rectangular lights drawn by
    solid angle")."""
    light = LightData("a", "AREA", WHITE, 100.0, frame((0.0, 0.0, 1.0)), size=1.6,
                      shape="SQUARE")
    # a wall across the light's nearer half seen from points beside it
    wall = quad_soup([[[-0.05, -2, -0.01], [-0.05, 2, -0.01], [-0.05, 2, 0.6], [-0.05, -2, 0.6]]])
    p = np.array([[x, y, 0.0] for x in (-0.2, -0.12, -0.08) for y in (-0.3, 0.0, 0.3)])
    n = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    ids = np.arange(len(p)) * 7 + 3
    truth = np.mean([diffuse_direct(p, n, [light], wall, samples=1024, seed=s,
                                    sample_ids=ids)[:, 0] for s in range(4)], axis=0)
    passes = np.mean([diffuse_direct(p, n, [light], wall, seed=s, sample_ids=ids,
                                     strata_block=(4, a, b, 1))[:, 0]
                      for s in range(64) for a in range(4) for b in range(4)], axis=0)
    lit = truth > 0.05 * truth.max()
    assert lit.sum() >= 6
    assert np.abs(passes[lit] / truth[lit] - 1.0).max() < 0.06, (passes / truth)

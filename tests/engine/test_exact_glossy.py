"""Exact one-bounce glossy reflections (voxgi_addon/gi/exact_glossy.py), the numpy reference of
shaders/bvh_glossy.glsl: energy under a uniform sky, mirrors, and what a glossy floor shows."""
import numpy as np
import pytest

from voxgi.voxgi_addon.gi.exact_glossy import glossy_indirect
from voxgi.voxgi_addon.gi.sampling import vndf_half_vectors
from voxgi.voxgi_addon.scene.geometry import SceneTriangles

ANGLES = np.radians([0.0, 30.0, 45.0, 60.0, 75.0, 85.0])


def far_speck():
    """One tiny triangle far away: a scene whose rays all see the world."""
    corners = np.array([[[100.0, 100.0, 100.0], [100.1, 100.0, 100.0], [100.0, 100.1, 100.0]]])
    return SceneTriangles(corners, np.array([[0.0, 0.0, 1.0]]), np.array([-1], np.int32),
                          np.zeros(1, np.int32))


def views():
    return np.stack([np.sin(ANGLES), np.zeros_like(ANGLES), np.cos(ANGLES)], axis=1)


def floor_points():
    count = len(ANGLES)
    return np.zeros((count, 3)), np.tile([0.0, 0.0, 1.0], (count, 1))


@pytest.mark.parametrize("roughness", [0.05, 0.2, 0.5, 0.9])
@pytest.mark.parametrize("metallic", [0.0, 1.0])
def test_a_white_sky_reflects_as_one(roughness, metallic):
    """Under a uniform sky of radiance 1 the glossy light is the lobe's albedo, which Glossy
    Color is: Glossy Indirect = 1 for every roughness, metal or not, and view (the tables the
    colour and the BSDF come from agree to a few percent at grazing views)."""
    p, n = floor_points()
    principled = (np.array([[0.8, 0.5, 0.2], [1.0, 1.0, 1.0]]),
                  np.array([[metallic, 0.5, roughness], [0.0, 0.5, 0.5]]))
    value, variance = glossy_indirect(p, n, views(), np.zeros(len(p), int), np.arange(len(p)),
                                      far_speck(), [], principled, np.zeros((2, 3)), rays=2048,
                                      world=(1.0, 1.0, 1.0))
    assert value.shape == (len(p), 3) and variance.shape == (len(p),)
    np.testing.assert_allclose(value[ANGLES <= np.radians(60)], 1.0, atol=0.025)
    np.testing.assert_allclose(value, 1.0, atol=0.06)


def test_visible_normals_face_the_view_and_the_normal():
    rng = np.random.default_rng(3)
    v = views()
    h = vndf_half_vectors(v, np.full(len(v), 0.3), rng.random((len(v), 256, 2)))
    np.testing.assert_allclose(np.linalg.norm(h, axis=-1), 1.0, atol=1e-9)
    assert (h[..., 2] >= 0.0).all()
    assert (np.einsum("nkc,nc->nk", h, v) > -1e-9).all()  # visible from the view
    smooth = vndf_half_vectors(v, np.full(len(v), 1e-4), rng.random((len(v), 16, 2)))
    np.testing.assert_allclose(smooth[..., 2], 1.0, atol=1e-6)  # α → 0: the normal itself


def test_a_metal_hit_is_followed_along_its_lobe():
    """``exact_indirect.metal_lobe_rays``: the direction a metal hit's path is followed along
    (the radiance cache's light read where the lobe points) is the mirror reflection for a
    smooth metal, and for a rough one spreads about it — its mean within the lobe's width of
    the mirror direction, different rays for different light-sample ids."""
    from voxgi.voxgi_addon.gi.exact_indirect import metal_lobe_rays

    n = 4096
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))
    arriving = np.tile(np.array([0.6, 0.0, -0.8]), (n, 1))  # 37° from the normal
    mirror = np.array([0.6, 0.0, 0.8])
    ids = np.arange(n, dtype=np.uint32)
    smooth = metal_lobe_rays(normals, arriving, np.zeros(n), ids)
    angle = np.degrees(np.arccos(np.clip(smooth @ mirror, -1.0, 1.0)))
    assert np.percentile(angle, 99) < 1.0  # α is held ≥ 1e-3: GGX's tail, barely
    rough = metal_lobe_rays(normals, arriving, np.full(n, 0.4), ids)
    np.testing.assert_allclose(np.linalg.norm(rough, axis=1), 1.0, atol=1e-9)
    spread = np.degrees(np.arccos(np.clip(rough @ mirror, -1.0, 1.0)))
    assert 3.0 < np.median(spread) < 25.0  # α = 0.16: a lobe of some ten degrees
    mean = rough.mean(axis=0)
    assert np.degrees(np.arccos(mean @ mirror / np.linalg.norm(mean))) < 8.0
    assert len(np.unique(np.round(rough, 6), axis=0)) > 0.99 * n
    assert not np.allclose(metal_lobe_rays(normals, arriving, np.full(n, 0.4), ids, seed=1), rough)


def test_a_mirror_shows_the_lit_wall_and_a_rough_floor_blurs_it():
    """A floor facing a glowing wall 2 m away, 4 m high: a mirror floor (roughness 0) seen at 45° shows the
    wall's radiance exactly where its reflection lands on the wall and nothing where it
    misses; a rough floor spreads the wall over its lobe (some light either way)."""
    wall = np.array([[[-5.0, 2.0, -1.0], [5.0, 2.0, -1.0], [5.0, 2.0, 3.0]],
                     [[-5.0, 2.0, -1.0], [5.0, 2.0, 3.0], [-5.0, 2.0, 3.0]]])
    tris = SceneTriangles(wall, np.tile([0.0, -1.0, 0.0], (2, 1)), np.zeros(2, np.int32),
                          np.zeros(2, np.int32))
    emission = np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])  # the wall glows with radiance ½
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]])  # the second's reflection passes over it
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    v = np.tile([0.0, -np.sqrt(0.5), np.sqrt(0.5)], (2, 1))  # reflection heads for +y
    for roughness, expect in ((0.0, [0.5, 0.0]), (0.4, None)):
        principled = (np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]),
                      np.array([[1.0, 0.5, roughness], [0.0, 0.5, 0.5]]))
        value, _ = glossy_indirect(p, n, v, np.zeros(2, int), np.arange(2), tris, [], principled,
                                   emission, rays=256)
        if expect is not None:
            np.testing.assert_allclose(value[:, 0], expect, atol=1e-6)
        else:
            assert 0.05 < value[0, 0] < 0.5 and value[1, 0] < value[0, 0]


def test_no_rays_no_points_and_back_facing_views_give_zero():
    p, n = floor_points()
    principled = (np.ones((1, 3)), np.array([[0.0, 0.5, 0.5]]))
    empty, var = glossy_indirect(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), [], [],
                                 far_speck(), [], principled, np.zeros((1, 3)))
    assert empty.shape == (0, 3) and var.shape == (0,)
    below = -views()
    value, _ = glossy_indirect(p, n, below, np.zeros(len(p), int), np.arange(len(p)), far_speck(),
                               [], principled, np.zeros((1, 3)), rays=8, world=(1.0, 1.0, 1.0))
    assert not value.any()


def _lobe_over_panel(p, n, v, corner, principled, radiance, side=1000):
    """∫ (BSDF × cos) L dω of the Principled lobe over the emitting triangles ``corner`` (T, 3,
    3) seen from p (normal n = +z), by a stratified side² grid of directions uniform on the
    hemisphere, each tested against the triangles: the brute force emitters_glossy is judged
    by (an area integral is too noisy for a panel a few centimetres away)."""
    from voxgi.voxgi_addon.gi.principled import glossy_reflectance
    base, params = principled
    u = (np.arange(side) + 0.5) / side
    z, phi = np.meshgrid(u, 2.0 * np.pi * u, indexing="ij")
    r = np.sqrt(1.0 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)
    hit = np.zeros(len(d), bool)
    for c in corner:  # Möller–Trumbore, rays from p
        e1, e2 = c[1] - c[0], c[2] - c[0]
        q = np.cross(d, e2)
        det = q @ e1
        s = p - c[0]
        a = (q @ s) / det
        b = (np.cross(s, e1) @ d.T) / det
        t = (np.cross(s, e1) @ e2) / det
        hit |= (a >= 0) & (b >= 0) & (a + b <= 1) & (t > 0)
    f = glossy_reflectance(base[0], params[0, 0], params[0, 1], params[0, 2], n, v, d)
    return (f * hit[:, None]).sum(axis=0) * (2.0 * np.pi / len(d)) * radiance


@pytest.mark.parametrize("view_angle, height, tolerance", [
    (30.0, 0.6, 0.05), (60.0, 0.6, 0.05), (80.0, 0.6, 0.05),
    (30.0, 0.05, 0.08), (60.0, 0.05, 0.2), (80.0, 0.05, 0.25)])
def test_an_emitter_near_a_grazing_dielectric_reflects_as_brute_force(view_angle, height,
                                                                      tolerance):
    """A rough white plastic floor (roughness 0.5) under a large emissive panel at ``height``
    ahead of its reflection, seen from ``view_angle``: the noise-free glossy light of the panel
    (LTC shape × the Fresnel where the lobe meets the panel) against the area integral of the
    Principled lobe. Measured: within 3.5% for the panel 0.6 m up (a white metal, whose
    Fresnel is 1, within 1% everywhere: the LTC shape is right); for the panel 5 cm up, which
    fills the lobe, 5%, 16% and 21% low at 30°, 60° and 80° (one Fresnel per triangle,
    at the lobe's mean direction over it, under-reads a convex Fresnel that varies across the
    whole lobe). Taken toward each triangle's centre (straight up for a panel 5 cm above) the
    Fresnel was 45–65% low there."""
    from voxgi.voxgi_addon.gi.emitters import emitter_light
    from voxgi.voxgi_addon.gi.exact_glossy import _Lobe, emitters_glossy

    a = np.radians(view_angle)
    p, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    v = np.array([-np.sin(a), 0.0, np.cos(a)])
    corner = np.array([[(-0.3, -0.8, height), (1.6, 0.8, height), (1.6, -0.8, height)],
                       [(-0.3, -0.8, height), (-0.3, 0.8, height), (1.6, 0.8, height)]])
    normals = np.tile([0.0, 0.0, -1.0], (2, 1))
    tris = SceneTriangles(corner, normals, np.zeros(2, np.int32), np.zeros(2, np.int32))
    emission = np.array([[5.0, 4.5, 4.0]])
    light = emitter_light(tris, emission)
    principled = (np.array([[0.8, 0.8, 0.8], [1.0, 1.0, 1.0]]),
                  np.array([[0.0, 0.5, 0.5], [0.0, 0.5, 0.5]]))
    lobe = _Lobe(n[None], v[None], np.zeros(1, int), principled)
    origins = np.broadcast_to(p + 1e-4 * n, (1, 16, 3))
    ours = emitters_glossy(lobe, light, tris, p[None], origins, np.arange(1), 16, 0)[0]
    expected = _lobe_over_panel(p, n, v, corner, principled, emission[0])
    np.testing.assert_allclose(ours, expected, rtol=tolerance)


def _sphere(centre, radius, segments=16, rings=8):
    """(T, 3, 3) a closed UV sphere's triangles, wound outward."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = 2.0 * np.pi * np.arange(segments) / segments
    p = np.stack([np.sin(theta)[:, None] * np.cos(phi)[None], np.sin(theta)[:, None] * np.sin(phi)[None],
                  np.broadcast_to(np.cos(theta)[:, None], (rings + 1, segments))], -1)
    p[0], p[-1] = p[0, 0], p[-1, 0]  # one point at each pole
    p = np.asarray(centre) + radius * p
    out = []
    for i in range(rings):
        for j in range(segments):
            k = (j + 1) % segments
            a, b, c, d = p[i, j], p[i + 1, j], p[i + 1, k], p[i, k]
            if i > 0:
                out.append((a, b, d))
            if i < rings - 1:
                out.append((b, c, d))
    return np.array(out)


@pytest.mark.parametrize("metallic", [0.0, 1.0])
def test_a_glowing_sphere_low_over_a_glossy_floor_reflects_as_brute_force(metallic):
    """A glowing sphere 3 m ahead and 0.5 m up of a rough floor (roughness 0.5) seen at 65°: its
    small triangles sit 8–13° above the floor's horizon, where the fitted LTC's density strays
    from the GGX lobe (it read this sphere 5.5% dark, the emissive room's glowing sphere on its
    floor 6–20%, a white metal and plastic alike); small triangles take the full lobe at their
    direction: within 2% of a hemisphere quadrature."""
    from voxgi.voxgi_addon.gi.emitters import emitter_light
    from voxgi.voxgi_addon.gi.exact_glossy import _Lobe, emitters_glossy

    a = np.radians(65.0)
    p, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    v = np.array([0.0, -np.sin(a), np.cos(a)])
    corner = _sphere((-0.4, 3.0, 0.5), 0.3)
    normals = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tris = SceneTriangles(corner, normals, np.zeros(len(corner), np.int32),
                          np.zeros(len(corner), np.int32))
    emission = np.array([[2.4, 4.8, 8.0]])
    light = emitter_light(tris, emission)
    assert (light.sides == 1).all()  # a closed mesh lights its outside only
    principled = (np.array([[0.7, 0.7, 0.7], [1.0, 1.0, 1.0]]),
                  np.array([[metallic, 0.5, 0.5], [0.0, 0.5, 0.5]]))
    lobe = _Lobe(n[None], v[None], np.zeros(1, int), principled)
    origins = np.broadcast_to(p + 1e-4 * n, (1, 16, 3))
    ours = emitters_glossy(lobe, light, tris, p[None], origins, np.arange(1), 16, 0)[0]
    expected = _lobe_over_panel(p, n, v, corner, principled, emission[0])
    np.testing.assert_allclose(ours, expected, rtol=0.02)


def test_an_emitting_panel_does_not_reflect_itself():
    """emitters_shine at points on a glowing panel (the pixels that see it): its own triangles
    lie in the points' horizon and send them nothing; a panel 0.6 m above still does. Without
    lifting the points off the plane, float rounding put half the panel above the horizon."""
    from voxgi.voxgi_addon.gi.emitters import emitter_light
    from voxgi.voxgi_addon.gi.exact_glossy import emitters_shine

    rng = np.random.default_rng(4)
    own = np.array([[(-1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (1.0, -1.0, 0.0)],
                    [(-1.0, -1.0, 0.0), (-1.0, 1.0, 0.0), (1.0, 1.0, 0.0)]])
    above = own + np.array([0.0, 0.0, 0.6])
    corner = np.concatenate([own, above])
    normals = np.tile([0.0, 0.0, -1.0], (4, 1))
    tris = SceneTriangles(corner, normals, np.zeros(4, np.int32), np.array([0, 0, 1, 1], np.int32))
    principled = (np.array([[0.8, 0.8, 0.8], [1.0, 1.0, 1.0]]),
                  np.array([[0.0, 0.5, 0.5], [0.0, 0.5, 0.5]]))
    points = np.concatenate([rng.uniform(-0.9, 0.9, (32, 2)), np.zeros((32, 1))], axis=1)
    points += rng.normal(0.0, 1e-7, points.shape) * [0, 0, 1]  # a float G-buffer's rounding
    views = np.tile([0.0, 0.3, 1.0], (32, 1)) / np.hypot(0.3, 1.0)
    up = np.tile([0.0, 0.0, 1.0], (32, 1))
    down = -up
    alone = emitter_light(SceneTriangles(own, normals[:2], np.zeros(2, np.int32),
                                         np.zeros(2, np.int32)), np.array([[5.0, 5.0, 5.0]]))
    np.testing.assert_array_equal(
        emitters_shine(points, down, -views, np.zeros(32, int), np.arange(32), tris, principled,
                       alone, rays=8), 0.0)
    both = emitter_light(tris, np.array([[5.0, 5.0, 5.0]]))
    lit = emitters_shine(points, up, views, np.zeros(32, int), np.arange(32), tris, principled,
                         both, rays=8)
    assert (lit > 0.0).all()


@pytest.mark.parametrize("view_angle", [70.0, 78.0, 85.0])
def test_a_panel_seen_edge_on_ahead_of_a_grazing_view_reflects_as_brute_force(view_angle):
    """The ceiling of the emissive room in front of its panel: the panel 5 cm out of the
    plane, starting 20 cm ahead of the point along its reflection and spanning 150° of it,
    seen from behind. The lobe over the LTC's density at the panel's mean direction stood
    for the whole panel and read it 1.7–2.7× too bright; trusted only as far as the
    triangle is narrow (exact_glossy._narrow) it is within 8% of the area integral."""
    from voxgi.voxgi_addon.gi.emitters import emitter_light
    from voxgi.voxgi_addon.gi.exact_glossy import _Lobe, emitters_glossy

    a = np.radians(view_angle)
    p, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    v = np.array([-np.sin(a), 0.0, np.cos(a)])
    corner = np.array([[(0.2, -0.8, 0.05), (1.2, 0.8, 0.05), (1.2, -0.8, 0.05)],
                       [(0.2, -0.8, 0.05), (0.2, 0.8, 0.05), (1.2, 0.8, 0.05)]])
    normals = np.tile([0.0, 0.0, 1.0], (2, 1))  # facing away: its back is seen
    tris = SceneTriangles(corner, normals, np.zeros(2, np.int32), np.zeros(2, np.int32))
    emission = np.array([[5.0, 4.5, 4.0]])
    principled = (np.array([[0.7, 0.7, 0.7], [1.0, 1.0, 1.0]]),
                  np.array([[0.0, 0.5, 0.5], [0.0, 0.5, 0.5]]))
    lobe = _Lobe(n[None], v[None], np.zeros(1, int), principled)
    origins = np.broadcast_to(p + 1e-4 * n, (1, 16, 3))
    ours = emitters_glossy(lobe, emitter_light(tris, emission), tris, p[None], origins,
                           np.arange(1), 16, 0)[0]
    expected = _lobe_over_panel(p, n, v, corner, principled, emission[0])
    np.testing.assert_allclose(ours, expected, rtol=0.12)


def test_the_diffuse_gathers_glossy_pick_chance_peaks_at_the_reflection():
    """The chance Cycles picked a diffuse-gather direction by the receiver's glossy closure
    (``glossy_pick_chance``: such a path keeps one more diffuse bounce): highest toward the
    view's reflection and the higher the sharper the lobe, near 0 far from it, 0 on a mirror
    (a diffuse direction is never its reflection) and for a receiver seen from behind."""
    from voxgi.voxgi_addon.gi.exact_glossy import glossy_pick_chance

    n = np.array([[0.0, 0.0, 1.0]])
    view = np.array([[np.sin(0.8), 0.0, np.cos(0.8)]])
    angles = np.linspace(-1.4, 1.4, 57)  # in the plane of incidence, from the normal
    dirs = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], axis=1)[None]
    reflection = np.argmin(np.abs(angles + 0.8))
    chances = {}
    for roughness in (0.0, 0.2, 0.5):
        principled = (np.array([[0.8, 0.8, 0.8], [0.8, 0.8, 0.8]]),
                      np.array([[0.0, 0.5, roughness], [0.0, 0.5, 0.5]]))
        chances[roughness] = glossy_pick_chance(n, view, np.array([0]), principled, dirs)[0]
        back = glossy_pick_chance(n, -view, np.array([0]), principled, dirs)[0]
        assert np.all(back == 0.0)
    assert np.all(chances[0.0] == 0.0)
    for roughness in (0.2, 0.5):
        chance = chances[roughness]
        assert np.all((chance >= 0.0) & (chance <= 1.0))
        assert abs(int(np.argmax(chance)) - reflection) <= 2, roughness
        assert chance[angles > 0.6].max() < 0.05, roughness  # the view's side, far from it
    assert chances[0.2].max() > 2.0 * chances[0.5].max() > 0.0

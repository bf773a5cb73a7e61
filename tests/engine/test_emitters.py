"""Emissive triangles as a light (voxgi_addon/gi/emitters.py) against numerical integrals."""
import dataclasses

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.emitters import (
    clipped_form_factors,
    emitter_distances,
    emitter_light,
    emitter_table,
    emitters_direct,
    emitting_sides,
    triangle_distances,
)
from voxgi.voxgi_addon.gi.sampling import hashed_square
from voxgi.voxgi_addon.scene.geometry import SceneTriangles


def triangles(corners, materials=None, objects=None):
    corners = np.asarray(corners, np.float64).reshape(-1, 3, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    count = len(corners)
    return SceneTriangles(corners, normals,
                          np.zeros(count, np.int32) if materials is None else np.asarray(materials, np.int32),
                          np.zeros(count, np.int32) if objects is None else np.asarray(objects, np.int32))


def form_factor_by_area(p, n, corner, samples=400_000):
    """∫ max(n·ω, 0)/π dω over a triangle by integrating over its area (either side)."""
    rng = np.random.default_rng(3)
    u = rng.random((samples, 2))
    s = np.sqrt(u[:, 0])
    points = (1 - s)[:, None] * corner[0] + (s * (1 - u[:, 1]))[:, None] * corner[1] \
        + (s * u[:, 1])[:, None] * corner[2]
    normal = np.cross(corner[1] - corner[0], corner[2] - corner[0])
    area = 0.5 * np.linalg.norm(normal)
    normal /= np.linalg.norm(normal)
    w = points - p
    r2 = (w * w).sum(1)
    d = w / np.sqrt(r2)[:, None]
    g = np.maximum(d @ n, 0) * np.abs(d @ normal) / r2
    return g.mean() * area / np.pi


@pytest.mark.parametrize("corner", [
    [(-1, -1, 2), (1, -1, 2), (0, 1, 2)],             # overhead
    [(2, -1, -1), (2, 1, -0.5), (2, 0, 1.5)],         # across the horizon
    [(-0.5, 0.3, 0.8), (0.7, -0.2, 0.1), (0.2, 0.9, 1.4)],
])
def test_clipped_form_factor_equals_the_area_integral(corner):
    corner = np.asarray(corner, np.float64)
    p, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    ours = clipped_form_factors(p[None], n[None], corner[None])[0, 0]
    assert ours == pytest.approx(form_factor_by_area(p, n, corner), rel=0.01)


def test_a_triangle_below_the_horizon_sheds_nothing():
    corner = np.array([[(-1, -1, -0.5), (1, -1, -0.5), (0, 1, -0.2)]], np.float64)
    assert clipped_form_factors(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), corner)[0, 0] == 0.0


def panel(z=2.0, size=1.0):
    return [[(-size, -size, z), (size, -size, z), (size, size, z)],
            [(-size, -size, z), (size, size, z), (-size, size, z)]]


def test_unoccluded_points_get_the_exact_sum_and_the_plain_estimate_converges_to_it():
    light = emitter_light(triangles(panel()), np.array([[2.0, 1.5, 1.0], [0.0, 0.0, 0.0]]))
    p = np.zeros((300, 3))
    n = np.tile([0.0, 0.0, 1.0], (300, 1))
    ids = np.arange(300)

    def strata(points):
        return hashed_square(ids[points], 0, 16)

    def open_sky(origins, dirs, lengths):
        return np.zeros(len(dirs), bool)

    exact = emitters_direct(light, p, n, open_sky, strata)
    by_area = 2 * form_factor_by_area(np.zeros(3), np.array([0, 0, 1.0]), np.array(panel()[0]))
    np.testing.assert_allclose(exact[0], by_area * np.array([2.0, 1.5, 1.0]), rtol=0.01)
    assert np.ptp(exact, axis=0).max() == 0.0  # no noise
    plain = emitters_direct(dataclasses.replace(light, exact=False), p, n, open_sky, strata)
    np.testing.assert_allclose(plain.mean(axis=0), exact[0], rtol=0.03)


def test_a_bounce_hit_beside_a_panel_reads_its_light_without_spikes():
    """At a bounce hit (exact False, one stratum a point) each picked triangle gives its own
    exact light over its pick's chance, less its sample's where hidden: 2 cm under a panel the
    hits read the exact sum on average with no 1/r² spike, and half the panel hidden still
    halves it (unbiased)."""
    light = dataclasses.replace(
        emitter_light(triangles(panel(z=0.02)), np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])),
        exact=False)
    count = 4000
    p = np.tile([0.3, -0.2, 0.0], (count, 1))
    n = np.tile([0.0, 0.0, 1.0], (count, 1))
    ids = np.arange(count)

    def one_stratum(points):
        return hashed_square(ids[points], 0, 1)

    def open_sky(origins, dirs, lengths):
        return np.zeros(len(dirs), bool)

    hits = emitters_direct(light, p, n, open_sky, one_stratum)[:, 0]
    exact = emitters_direct(dataclasses.replace(light, exact=True), p[:1], n[:1], None, None)[0, 0]
    assert hits.mean() == pytest.approx(exact, rel=0.02)
    assert hits.max() <= 2.0 * exact  # the two triangles' shares: no sample far above them

    def behind_a_wall(origins, dirs, lengths):  # blocks every ray towards x > 0
        return dirs[:, 0] > 0

    far = dataclasses.replace(light, corners=light.corners + np.array([0.0, 0.0, 1.98]))
    centre = np.zeros((count, 3))
    half = emitters_direct(far, centre, n, behind_a_wall, one_stratum)[:, 0]
    full = emitters_direct(dataclasses.replace(far, exact=True), centre[:1], n[:1], None, None)
    assert half.mean() == pytest.approx(0.5 * full[0, 0], rel=0.05)


def test_half_the_panel_hidden_halves_its_light():
    light = emitter_light(triangles(panel()), np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]))
    ids = np.arange(400)

    def behind_a_wall(origins, dirs, lengths):  # blocks every ray towards x > 0
        return dirs[:, 0] > 0

    value = emitters_direct(light, np.zeros((400, 3)), np.tile([0.0, 0.0, 1.0], (400, 1)),
                            behind_a_wall, lambda pts: hashed_square(ids[pts], 0, 16))
    full = emitters_direct(light, np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), None, None)
    assert value.mean(axis=0)[0] == pytest.approx(0.5 * full[0, 0], rel=0.05)


def box(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], np.float64)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return np.array([v[[a, b, c]] for q in quads for a, b, c in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])


def test_closed_emitters_light_their_outside_and_open_ones_both_sides():
    closed = box((0, 0, 0), (1, 1, 1))
    open_panel = np.array(panel(3.0))
    corners = np.concatenate([closed, open_panel])
    objects = np.array([0] * len(closed) + [1] * len(open_panel))
    sides = emitting_sides(corners, objects)
    assert set(sides[:len(closed)]) == {1} and set(sides[len(closed):]) == {0}
    assert set(emitting_sides(closed[:, ::-1], np.zeros(len(closed), int))) == {-1}  # inward


def test_a_glowing_cube_seen_from_outside_is_counted_once():
    light = emitter_light(triangles(box((-0.5, -0.5, 2.0), (0.5, 0.5, 3.0))), np.array([[1.0] * 3, [0.0] * 3]))
    value = emitters_direct(light, np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), None, None)
    bottom = 2 * form_factor_by_area(np.zeros(3), np.array([0, 0, 1.0]),
                                     np.array([(-0.5, -0.5, 2.0), (0.5, -0.5, 2.0), (0.5, 0.5, 2.0)]))
    # straight below it only the bottom face's outside faces the point (the sides' and top's
    # insides would double it)
    assert value[0, 0] == pytest.approx(bottom, rel=0.01)


def test_nothing_emits_gives_no_light_and_an_empty_table():
    assert emitter_light(triangles(panel()), np.zeros((2, 3))) is None
    assert emitter_table(None).shape == (1, 4, 4) and not emitter_table(None).any()


def test_triangle_distances_are_the_nearest_points_of_the_triangles():
    """Ericson's closest point (the GLSL's emitter_distance) against a dense sampling of each
    triangle: never farther, and within the sampling's spacing."""
    rng = np.random.default_rng(5)
    corners = rng.normal(size=(20, 3, 3))
    points = rng.normal(size=(100, 3)) * 2.0
    u = rng.random((40_000, 2))
    u[u.sum(1) > 1] = 1 - u[u.sum(1) > 1]
    samples = corners[:, None, 0] + u[None, :, :1] * (corners[:, None, 1] - corners[:, None, 0]) \
        + u[None, :, 1:] * (corners[:, None, 2] - corners[:, None, 0])          # (T, S, 3)
    sampled = np.linalg.norm(points[:, None, None] - samples[None], axis=-1).min(-1)
    exact = triangle_distances(points, corners)
    assert (exact <= sampled + 1e-9).all() and (sampled - exact).max() < 0.05


def test_the_emitters_distance_counts_only_triangles_that_light_the_point():
    """A point on a glowing panel is not near it (its own triangles lie in its horizon), a point
    5 cm over the panel's back is (an open panel lights both sides), and a point outside a
    glowing cube is as far as the cube's nearest face that faces it."""
    light = emitter_light(triangles(panel(3.0)), np.array([[1.0] * 3, [0.0] * 3]))
    z = light.corners[0, 0, 2]
    up = np.array([[0.0, 0.0, 1.0]])
    assert emitter_distances(light, [[0.0, 0.0, z + 1e-4]], up)[0] > 1e29
    assert emitter_distances(light, [[0.0, 0.0, z + 0.05]], -up)[0] == pytest.approx(0.05)
    cube = emitter_light(triangles(box((0, 0, 0), (1, 1, 1))), np.array([[1.0] * 3, [0.0] * 3]))
    assert emitter_distances(cube, [[0.5, 0.5, 1.3]], -up)[0] == pytest.approx(0.3)


def uv_sphere(segments, rings, radius, centre=(0.0, 0.0, 0.0)):
    """(T, 3, 3) a UV sphere's triangles, wound outward, as Blender's primitive makes them."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)

    def at(i, j):
        return np.asarray(centre) + radius * np.array([np.sin(theta[i]) * np.cos(phi[j]),
                                                       np.sin(theta[i]) * np.sin(phi[j]),
                                                       np.cos(theta[i])])
    out = []
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)
            if i > 0:
                out.append([a, b, d])
            if i < rings - 1:
                out.append([b, c, d])
    return np.array(out)


def test_an_emitter_of_thousands_of_triangles_lights_as_its_own_triangles_do(monkeypatch):
    """A glowing 64 × 32 UV sphere (3,968 triangles, past MAX_EMITTER_TRIANGLES) is still a
    light: its exact sums run over a proxy of at most PROXY_TRIANGLES that sends the same power,
    its shadow rays go to its own triangles. Under it, a floor reads the light the full sums
    read, to 2% (1.0% measured), shadowed by the sphere itself as those are; its own surface is not
    lit by its proxy. Before, such an emitter was no light at all (its emission only seen by
    the gathers' rays)."""
    from voxgi.voxgi_addon.gi import emitters as module
    from voxgi.voxgi_addon.scene.raycast import occluded

    corners = uv_sphere(64, 32, 0.3)
    tris = triangles(corners)
    emission = np.array([[2.4, 4.8, 8.0], [0.0, 0.0, 0.0]])
    light = emitter_light(tris, emission)
    assert light is not None and len(light.corners) == len(corners) > module.MAX_EMITTER_TRIANGLES
    assert light.sums is not None and len(light.sums.corners) <= module.PROXY_TRIANGLES
    power = lambda part: (part.area[:, None] * part.radiance).sum(axis=0)  # noqa: E731
    assert np.allclose(power(light.sums), power(light), rtol=1e-5)
    with monkeypatch.context() as m:  # the full sums, for the reference
        m.setattr(module, "MAX_EMITTER_TRIANGLES", 10_000)
        whole = emitter_light(tris, emission)
    assert whole.sums is None
    grid = np.stack(np.meshgrid(np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9)), -1)
    p = np.concatenate([grid.reshape(-1, 2), np.full((81, 1), -0.5)], axis=1)
    n = np.tile([[0.0, 0.0, 1.0]], (len(p), 1))

    def shadowed(of):
        return emitters_direct(of, p, n, lambda o, d, t: occluded(tris, o, d, t),
                               lambda idx: hashed_square(idx, 64, 5, 0))
    ours, reference = shadowed(light), shadowed(whole)
    assert reference.mean() > 0.1
    assert np.abs(ours - reference).sum() / np.abs(reference).sum() < 0.02
    # the sphere's own points, a hair outside it: lit by neither
    on = corners.mean(axis=1)[::31]
    out = on / np.linalg.norm(on, axis=1, keepdims=True)
    from voxgi.voxgi_addon.gi.emitters import unshadowed_sum
    assert unshadowed_sum(light, on + 1e-4 * out, out).max() < 1e-3
    # the table holds the triangles, then the proxy the sums run over
    table = emitter_table(light)
    assert len(table) == len(light.corners) + len(light.sums.corners) + 1
    assert tuple(table[-1, 1, :2]) == (len(light.corners), len(light.sums.corners))


def test_many_small_glowing_objects_keep_their_light_each(monkeypatch):
    """Fairy lights: 30 glowing 16 × 8 spheres of 4 cm, each its own object (6,720 triangles).
    The proxy is clustered object by object, each its share of a budget of PROXY_PER_OBJECT
    triangles an object (at most MAX_EMITTER_TRIANGLES), each object's power kept: a floor
    under them reads the full sums' unshadowed light within 6% (5.0% measured: 18 triangles a
    sphere). One grid over the whole string (256 triangles, some spheres gone) read 11% off, and
    the room it lit 0.0752 against Cycles 512 spp, over Cycles 16 spp + OIDN's 0.070; clustered
    object by object, 0.0368 (the full sums: 0.0367)."""
    from voxgi.voxgi_addon.gi import emitters as module
    from voxgi.voxgi_addon.gi.emitters import unshadowed_sum

    rng = np.random.default_rng(4)
    centres = np.column_stack([rng.uniform(-2.0, 2.0, 30), rng.uniform(-1.0, 1.0, 30),
                               rng.uniform(1.8, 2.2, 30)])
    corners = np.concatenate([uv_sphere(16, 8, 0.04, c) for c in centres])
    objects = np.repeat(np.arange(30), len(corners) // 30)
    tris = triangles(corners, objects=objects)
    emission = np.array([[30.0, 24.0, 15.0], [0.0, 0.0, 0.0]])
    light = emitter_light(tris, emission)
    assert light.sums is not None
    assert len(light.sums.corners) <= module.MAX_EMITTER_TRIANGLES
    with monkeypatch.context() as m:
        m.setattr(module, "MAX_EMITTER_TRIANGLES", 10_000)
        whole = emitter_light(tris, emission)
    grid = np.stack(np.meshgrid(np.linspace(-2.5, 2.5, 11), np.linspace(-1.5, 1.5, 7)), -1)
    p = np.concatenate([grid.reshape(-1, 2), np.zeros((77, 1))], axis=1)
    n = np.tile([[0.0, 0.0, 1.0]], (len(p), 1))
    ours, reference = unshadowed_sum(light, p, n), unshadowed_sum(whole, p, n)
    assert reference.mean() > 0.01
    assert np.abs(ours - reference).sum() / np.abs(reference).sum() < 0.06

"""LTC for the Principled GGX lobe (voxgi_addon/gi/ltc.py, table by tools/fit_ltc.py;
docs/gi_pipeline.md "LTC: the glossy lobe over polygons"): triangle integrals against a
visible-normal quadrature of the lobe, the hemisphere's integral, the horizon, the table's
continuity."""
import math

import numpy as np
import pytest

from voxgi.voxgi_addon.gi import ltc
from voxgi.voxgi_addon.gi import principled as pr

ROUGHNESS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)


def view_dir(mu):
    return np.array([math.sqrt(max(1.0 - mu * mu, 0.0)), 0.0, mu])


def grid(n):
    u = (np.arange(n) + 0.5) / n
    a, b = np.meshgrid(u, u, indexing="ij")
    return a.ravel(), b.ravel()


def reference(rough, mu, tris, n=512):
    """(T,) ∫_tri ρ for the local frame (normal z, view in x–z) by an n² quadrature of the GGX
    visible normals: ρ / pdf = (G2/G1) / E for reflections above the horizon."""
    alpha = rough * rough
    _, w, _ = pr._sample_vndf(mu, alpha, *grid(n))
    up = w[:, 2] > 0
    li = pr._ggx_lambda(alpha * alpha, mu)
    lo = pr._ggx_lambda(alpha * alpha, np.where(up, w[:, 2], 1.0))
    weight = np.where(up, (1 + li) / (1 + li + lo), 0.0)
    weight /= weight.sum()
    out = np.zeros(len(tris))
    for t, c in enumerate(tris):
        sign = np.sign(np.dot(np.cross(c[0], c[1]), c[2]))
        inside = np.ones(len(w), bool)
        for k in range(3):
            inside &= sign * (w @ np.cross(c[k], c[(k + 1) % 3])) >= 0
        out[t] = weight[inside].sum()
    return out


def triangles(rng, centre_hint, count, spread):
    """Unit-direction triangles: even ones near ``centre_hint`` (the lobe), odd ones anywhere
    above or across the horizon; angular radii log-uniform from ~spread/3 to 1.2 rad."""
    out = []
    for t in range(count):
        if t % 2 == 0:
            centre = centre_hint + rng.normal(size=3) * spread
        else:
            centre = rng.normal(size=3)
            centre[2] = abs(centre[2])
        centre /= np.linalg.norm(centre)
        radius = math.exp(rng.uniform(math.log(max(0.3 * spread, 0.01)), math.log(1.2)))
        a = np.cross(centre, [0.3, 0.5, 0.8])
        a /= np.linalg.norm(a)
        b = np.cross(centre, a)
        angles = rng.uniform(0, 2 * math.pi) + np.arange(3) * 2 * math.pi / 3 + rng.uniform(-0.6, 0.6, 3)
        corners = centre + radius * (np.cos(angles)[:, None] * a + np.sin(angles)[:, None] * b)
        out.append(corners / np.linalg.norm(corners, axis=1, keepdims=True))
    return np.array(out)


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_table_shape_and_sanity():
    table = ltc.load_table()
    minv = table["minv"]
    assert minv.shape == (len(table["roughness"]), len(table["view_x"]), 4)
    assert ltc.TABLE_PATH.stat().st_size < 64 * 1024
    a, b, c, d = np.moveaxis(minv, -1, 0)
    assert np.isfinite(minv).all()
    assert (a > 0).all() and (c > 0).all() and (a - b * d > 0).all()
    # normal incidence is rotationally symmetric: b = d = 0, a = c (fitted so)
    assert np.all(b[:, 0] == 0) and np.all(d[:, 0] == 0)
    assert np.allclose(a[:, 0], c[:, 0], rtol=1e-6)
    # the parameters the lookup blends reproduce the cells
    assert np.allclose(ltc._abcd(ltc._params(minv)), minv, rtol=1e-9, atol=1e-9 * np.abs(minv).max())


@pytest.mark.parametrize("rough", ROUGHNESS)
def test_triangles_match_the_lobe(rough):
    """Random views and triangles (world frames: random normal, position, distance): LTC vs an
    independent 512² visible-normal quadrature of ρ. Errors relative to 1 (the lobe's total)
    and relative to the triangle's integral (triangles holding ≥ 5% of the lobe)."""
    rng = np.random.default_rng(int(rough * 1000))
    absolute, relative = [], []
    for mu in np.linspace(0.1, 1.0, 6):
        rot = random_rotation(rng)          # local → world
        p = rng.normal(size=3)
        v_local = view_dir(mu)
        mirror = np.array([-v_local[0], 0.0, mu])
        tris = triangles(rng, mirror, 24, spread=max(2 * rough * rough, 0.02))
        expected = reference(rough, mu, tris)
        distance = rng.uniform(0.5, 5.0, (len(tris), 1, 1))
        corners = p + (tris * distance) @ rot.T
        got = ltc.ltc_polygon_integral(p, rot[:, 2], rot @ v_local, rough, corners)[0]
        absolute.extend(np.abs(got - expected))
        big = expected >= 0.05
        relative.extend(np.abs(got - expected)[big] / expected[big])
    absolute, relative = np.array(absolute), np.array(relative)
    print(f"roughness {rough}: |err| mean {absolute.mean():.4f} p95 {np.percentile(absolute, 95):.4f} "
          f"max {absolute.max():.4f}; relative mean {relative.mean():.3f} p95 {np.percentile(relative, 95):.3f}")
    assert np.percentile(absolute, 95) <= 0.06
    assert absolute.max() <= 0.15
    assert np.percentile(relative, 95) <= 0.35


@pytest.mark.parametrize("rough", [0.0, 0.05, 0.1, 0.4, 1.0])
def test_hemisphere_integrates_to_one(rough):
    """An octahedron around the point (the triangles below the horizon clip away) sums to 1
    for every view; tilted frames, far and near."""
    rng = np.random.default_rng(7)
    octa = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    tris = []
    for pole in ([0, 0, 1.0], [0, 0, -1.0]):
        for k in range(4):
            tris.append([octa[k], octa[(k + 1) % 4], pole])
    tris = np.array(tris)
    for mu in (1.0, 0.7, 0.3, 0.05, 0.001):
        rot = random_rotation(rng)
        p = rng.normal(size=3)
        corners = p + (tris * rng.uniform(0.1, 10)) @ rot.T
        n = rot @ np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
        t = np.cross(n, rng.normal(size=3))
        t /= np.linalg.norm(t)
        v = mu * n + math.sqrt(1 - mu * mu) * t
        total = ltc.ltc_polygon_integral(p, n, v, rough, corners).sum()
        assert total == pytest.approx(1.0, abs=1e-6)


def test_below_the_horizon_is_zero():
    rng = np.random.default_rng(11)
    n = np.array([0.0, 0.0, 1.0])
    corners = rng.normal(size=(50, 3, 3))
    corners[..., 2] = -np.abs(corners[..., 2]) - 1e-3
    for rough in (0.05, 0.3, 1.0):
        for mu in (1.0, 0.5, 0.02):
            got = ltc.ltc_polygon_integral(np.zeros(3), n, view_dir(mu), rough, corners)
            assert np.all(got == 0.0)
    # a triangle across the horizon counts only its part above
    across = np.array([[[-1.0, -1.0, -0.5], [1.0, -1.0, -0.5], [0.0, 1.0, 0.5]]])
    above = np.array([[[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.5]]])
    for mu in (1.0, 0.4):
        a = ltc.ltc_polygon_integral(np.zeros(3), n, view_dir(mu), 0.5, across)
        b = ltc.ltc_polygon_integral(np.zeros(3), n, view_dir(mu), 0.5, above)
        assert a == pytest.approx(b, rel=1e-9)
    # a view below the surface sees nothing
    cap = np.array([[[1.0, 0.0, 1.0], [-1.0, 1.0, 1.0], [-1.0, -1.0, 1.0]]])
    assert ltc.ltc_polygon_integral(np.zeros(3), n, -view_dir(0.5), 0.5, cap)[0, 0] == 0.0


def test_table_is_continuous():
    """No cell departs from its neighbours: the fit's parameters (lobe direction, log spreads,
    skew; what the lookup blends) are close to the blend of their neighbours, and triangles'
    integrals have small second differences at the nodes where lobes are wider than a grid step (roughness ≥ 0.25);
    between nodes the lookup is continuous (fine sweeps have no jump)."""
    table = ltc.load_table()
    rough, view_x = table["roughness"], table["view_x"]
    # the grazing column (cos θ_v = 0, fitted at 10⁻³) holds a degenerate lobe: left out
    params = ltc._params(table["minv"])[:, :-1]
    # a node against the blend of its two neighbours (rows: linear in log roughness)
    log_r = np.log(np.maximum(rough, table["rough_min"]))
    w = ((log_r[2:] - log_r[1:-1]) / (log_r[2:] - log_r[:-2]))[:, None, None]
    dev_r = np.abs(params[1:-1] - (w * params[:-2] + (1 - w) * params[2:]))
    dev_v = np.abs(params[:, 1:-1] - 0.5 * (params[:, :-2] + params[:, 2:]))
    # κ (the skew) grows as the lobe nears the horizon: compare it relative to its size
    dev_r[..., 3] /= 1 + np.abs(params[1:-1, :, 3])
    dev_v[..., 3] /= 1 + np.abs(params[:, 1:-1, 3])
    print("node vs its neighbours' blend (φ, log s_x, log s_y, κ relative): along roughness",
          np.round(dev_r.max(axis=(0, 1)), 3), "along the view", np.round(dev_v.max(axis=(0, 1)), 3))
    assert dev_r[..., :3].max() <= 0.2 and dev_v[..., :3].max() <= 0.2
    assert dev_r[..., 3].max() <= 0.5 and dev_v[..., 3].max() <= 0.5

    cos_view = 1.0 - view_x ** 2
    tris = triangles(np.random.default_rng(3), np.array([0.0, 0.0, 1.0]), 16, spread=0.8)
    wide = rough >= 0.25
    values = np.zeros((wide.sum(), len(view_x), len(tris)))
    for j, mu in enumerate(cos_view):
        values[:, j] = ltc.ltc_polygon_integral(np.zeros(3), [0, 0, 1.0], view_dir(max(mu, 1e-3)),
                                                rough[wide], tris)
    worst_r = np.abs(values[2:] - 2 * values[1:-1] + values[:-2]).max()
    worst_v = np.abs(values[:, 2:] - 2 * values[:, 1:-1] + values[:, :-2]).max()
    print(f"triangle integrals' second differences (roughness ≥ 0.25): along roughness {worst_r:.4f},"
          f" along the view {worst_v:.4f}")
    assert worst_r <= 0.05 and worst_v <= 0.1

    fine = np.linspace(0.0, 1.0, 2001)
    sweep = ltc.ltc_polygon_integral(np.zeros(3), [0, 0, 1.0], view_dir(0.6), fine, tris)
    assert np.abs(np.diff(sweep, axis=0)).max() <= 0.01
    cos = 1.0 - fine[:-1] ** 2             # uniform in the table's view axis
    views = np.stack([np.sqrt(1 - cos ** 2), 0 * cos, cos], -1)
    sweep = ltc.ltc_polygon_integral(np.zeros(3), [0, 0, 1.0], views, 0.4, tris)
    assert np.abs(np.diff(sweep, axis=0)).max() <= 0.01


def test_lookup_matches_nodes_and_clamps():
    table = ltc.load_table()
    rough, view_x, minv = table["roughness"], table["view_x"], table["minv"]
    got = ltc.ltc_inverse(rough[5], 1.0 - view_x[7] ** 2)
    assert got[0, 0] == pytest.approx(minv[5, 7, 0], rel=1e-6)
    assert got[0, 2] == pytest.approx(minv[5, 7, 1], rel=1e-6, abs=1e-9)
    assert got[1, 1] == pytest.approx(minv[5, 7, 2], rel=1e-6)
    assert got[2, 0] == pytest.approx(minv[5, 7, 3], rel=1e-6, abs=1e-9)
    assert got[2, 2] == 1.0
    assert np.allclose(ltc.ltc_inverse(-1.0, 2.0), ltc.ltc_inverse(0.0, 1.0))
    assert np.allclose(ltc.ltc_inverse(3.0, -1.0), ltc.ltc_inverse(1.0, 0.0))

"""The Principled BSDF model (voxgi_addon/gi/principled.py; docs/gi_pipeline.md "Principled
materials"): limit cases, energy bounds (white furnace) and the tables against independent
integration."""
import numpy as np
import pytest

from voxgi.voxgi_addon.gi import principled as pr

N = np.array([0.0, 0.0, 1.0])


def direction(cos_theta, phi=0.0):
    s = np.sqrt(np.maximum(1.0 - np.asarray(cos_theta) ** 2, 0.0))
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), cos_theta), axis=-1)


def hemisphere_grid(n_theta=256, n_phi=512):
    """Midpoint directions over the upper hemisphere and their solid angles."""
    theta = (np.arange(n_theta) + 0.5) * (np.pi / 2) / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return d.reshape(-1, 3), (np.sin(t) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)).ravel()


def glossy_albedo(base, metallic, level, roughness, mu):
    """∫ glossy_reflectance over the light directions for the view at cosine ``mu`` (…, 3)."""
    lights, weights = hemisphere_grid()
    view = direction(mu)
    values = pr.glossy_reflectance(base, metallic, level, roughness, N, view, lights)
    return (values * weights[:, None]).sum(axis=0)


def test_specular_level_zero_is_plain_lambert():
    base = np.array([0.9, 0.4, 0.1])
    mu = np.linspace(0.01, 1.0, 7)
    for rough in (0.05, 0.5, 1.0):
        np.testing.assert_allclose(pr.diffuse_weight(base, 0.0, 0.0, rough, mu),
                                   np.broadcast_to(base, (7, 3)))
        assert np.all(pr.glossy_color(base, 0.0, 0.0, rough, mu) == 0.0)
        assert np.all(pr.glossy_reflectance(base, 0.0, 0.0, rough, N, direction(mu),
                                            direction(0.7, 2.0)) == 0.0)
    f0, eta = pr.specular_f0_eta([0.0, 0.5, 1.0])
    np.testing.assert_allclose(f0, [0.0, 0.04, 0.08])
    np.testing.assert_allclose(eta, [1.0, 1.5, pr._ior_from_f0(0.08)])


def test_metal_has_no_diffuse_and_a_coloured_glossy():
    base = np.array([1.0, 0.77, 0.34])
    mu = np.linspace(0.05, 1.0, 5)
    assert np.all(pr.diffuse_weight(base, 1.0, 0.5, 0.4, mu) == 0.0)
    color = pr.glossy_color(base, 1.0, 0.5, 0.4, mu)
    # About F0 = base colour or more, at most 1, the red channel above the blue
    # (the Kulla–Conty darkening E + F_ms (1 − E) may take a coloured metal a little below F0).
    assert np.all(color >= 0.95 * base) and np.all(color <= 1.0 + 1e-9)
    assert np.all(color[:, 0] > color[:, 2])
    half = pr.diffuse_weight(base, 0.5, 0.5, 0.4, mu)
    np.testing.assert_allclose(half, 0.5 * pr.diffuse_weight(base, 0.0, 0.5, 0.4, mu))


def test_dielectric_layer_takes_energy_from_the_diffuse_base():
    base = np.ones(3)
    mu = np.linspace(0.05, 1.0, 20)
    for rough in (0.1, 0.5, 0.9):
        weight = pr.diffuse_weight(base, 0.0, 0.5, rough, mu)[:, 0]
        assert np.all(weight < 0.99) and np.all(weight > 0.2)
        # The specular layer reflects more at grazing angles: less diffuse there than head-on.
        assert weight[0] < weight[-1]
    # A stronger specular level leaves less to the diffuse base.
    levels = pr.diffuse_weight(base, 0.0, np.array([0.25, 0.5, 1.0]), 0.5, 0.6)[:, 0]
    assert levels[0] > levels[1] > levels[2]


@pytest.mark.parametrize("rough", [0.2, 0.5, 0.8, 1.0])
@pytest.mark.parametrize("mu", [0.2, 0.6, 1.0])
def test_white_furnace(rough, mu):
    # A white metal reflects everything: multiple-scattering compensation restores the energy
    # the single-scattering GGX lobe loses.
    metal = glossy_albedo(np.ones(3), 1.0, 0.5, rough, mu)
    np.testing.assert_allclose(metal, 1.0, atol=0.01)
    np.testing.assert_allclose(pr.glossy_color(np.ones(3), 1.0, 0.5, rough, mu), 1.0)
    # A white dielectric: diffuse (Lambert albedo = Diffuse Color) + glossy never exceeds 1,
    # and loses little (the layering uses the estimated albedo of the specular lobe).
    total = pr.diffuse_weight(np.ones(3), 0.0, 0.5, rough, mu) + glossy_albedo(
        np.ones(3), 0.0, 0.5, rough, mu)
    assert np.all(total <= 1.01) and np.all(total >= 0.98), total
    # Glossy Color is the estimate of that glossy albedo.
    np.testing.assert_allclose(glossy_albedo(np.ones(3), 0.0, 0.5, rough, mu),
                               pr.glossy_color(np.ones(3), 0.0, 0.5, rough, mu), rtol=0.1)


def test_glossy_direct_times_glossy_color_is_the_glossy_reflectance():
    rng = np.random.default_rng(1)
    base = rng.uniform(0, 1, (50, 3))
    view, light = direction(rng.uniform(0.1, 1, 50)), direction(rng.uniform(0.1, 1, 50), 2.5)
    mu = view[:, 2]
    for metallic in (0.0, 0.6, 1.0):
        color = pr.glossy_color(base, metallic, 0.5, 0.4, mu)
        np.testing.assert_allclose(color * pr.glossy_direct(base, metallic, 0.5, 0.4, N, view, light),
                                   pr.glossy_reflectance(base, metallic, 0.5, 0.4, N, view, light))


def test_outgoing_radiance_is_diffuse_plus_glossy_and_broadcasts():
    base = np.full((4, 5, 3), 0.5)
    view = np.broadcast_to(direction(0.8), (4, 5, 3))
    light = direction(0.6, 1.0)
    out = pr.outgoing_radiance(base, 0.0, 0.5, 0.5, N, view, light, 2.0)
    assert out.shape == (4, 5, 3)
    diffuse = pr.diffuse_weight(base, 0.0, 0.5, 0.5, 0.8) * 0.6 / np.pi
    glossy = pr.glossy_reflectance(base, 0.0, 0.5, 0.5, N, view, light)
    np.testing.assert_allclose(out, 2.0 * (diffuse + glossy))
    # Lit from below or seen from below: nothing.
    assert np.all(pr.outgoing_radiance(base, 0.0, 0.5, 0.5, N, view, -light, 2.0) == 0.0)
    assert np.all(pr.outgoing_radiance(base, 0.0, 0.5, 0.5, N, -view, light, 2.0) == 0.0)


def test_lookup_is_piecewise_linear_between_grid_points():
    table = np.arange(4 * 5 * 6, dtype=float).reshape(4, 5, 6) ** 1.5
    assert pr.lookup(table, 2 / 5, 1 / 4, 2 / 3) == table[2, 1, 2]
    np.testing.assert_allclose(pr.lookup(table, 0.1, 0.0, 0.0), 0.5 * (table[0, 0, 0] + table[0, 0, 1]))
    np.testing.assert_allclose(pr.lookup(table, 0.0, 0.0, 1 / 6), 0.5 * (table[0, 0, 0] + table[1, 0, 0]))
    assert pr.lookup(table, -1.0, 2.0, 5.0) == table[3, 4, 0]  # clamped


def test_stored_tables_match_their_definition():
    luts = pr.load_luts()
    # Spot cells recomputed by the generator's quadrature.
    for m, r in ((3, 7), (16, 16), (31, 31), (0, 20)):
        assert abs(luts["ggx_E"][m, r] - pr._cell(max(r / 31, 1e-4), max(m / 31, 1e-4), 256)) < 1e-4
    z, m, r = 6, 5, 9
    eta = pr._ior_of_z(z / 15)
    assert abs(luts["ior_s"][z, m, r] - pr._cell(r / 15, m / 15, 256, pr._ior_s(eta))) < 1e-4
    # E against brute force over a grid of light directions (no visible-normal sampling).
    lights, weights = hemisphere_grid(512, 512)
    for rough, mu in ((0.5, 0.5), (0.8, 0.9), (0.3, 0.2)):
        alpha = rough * rough
        v = direction(mu)
        h = lights + v
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        e = (pr._ggx_eval(alpha, mu, lights[:, 2], h[:, 2]) * weights).sum()
        assert abs(pr.lookup(luts["ggx_E"], rough, mu) - e) < 3e-3, (rough, mu)
    # E_avg = ∫ 2 μ E dμ.
    mus = (np.arange(2000) + 0.5) / 2000
    for rough in (0.3, 0.7, 1.0):
        average = np.mean(2 * mus * pr.lookup(luts["ggx_E"], rough, mus))
        assert abs(pr.lookup(luts["ggx_Eavg"], rough) - average) < 3e-3
    assert pr.lut_texels().shape == (305, 32, 4)


def test_tabulated_colours_of_a_big_image_equal_the_direct_evaluation():
    """preview.passes.principled_colours interpolates per-material tables over cos(view) when
    there are more pixels than table entries: a metal, a glossy dielectric, a rough one."""
    from snapshots import snapshot

    from voxgi.voxgi_addon.preview.passes import COLOUR_BINS, principled_colours, principled_table
    from voxgi.voxgi_addon.scene.snapshot import MaterialData

    materials = [MaterialData("metal", np.array([0.9, 0.6, 0.3], np.float32), 0.05, 1.0),
                 MaterialData("glossy", np.array([0.2, 0.4, 0.8], np.float32), 0.15, 0.0, 0.9),
                 MaterialData("rough", np.array([0.8, 0.8, 0.8], np.float32), 0.9, 0.3)]
    scene = snapshot([], [], materials)
    rng = np.random.default_rng(5)
    count = 5 * COLOUR_BINS  # more than the 4 materials' (with "none") table entries
    mat = rng.integers(0, 4, count)
    cos_view = np.concatenate([rng.random(count - 3), [0.0, 1e-6, 1.0]])
    diffuse, glossy = principled_colours(scene, mat, cos_view)
    base, params = principled_table(scene)
    args = (base[mat], params[mat, 0], params[mat, 1], params[mat, 2], cos_view)
    np.testing.assert_allclose(diffuse, pr.diffuse_weight(*args), atol=2e-4)
    np.testing.assert_allclose(glossy, pr.glossy_color(*args), atol=2e-4)


def test_nan_material_inputs_fall_back_to_the_defaults():
    """A NaN roughness or metallic (a broken driver, a bad import) must not turn every ray
    that meets the material into NaN: the table keeps the Principled defaults instead."""
    from snapshots import snapshot

    from voxgi.voxgi_addon.preview.passes import principled_table
    from voxgi.voxgi_addon.scene.snapshot import MaterialData

    nan = float("nan")
    broken = MaterialData("broken", np.array([nan, 0.5, 0.2], np.float32), nan, nan, 2.0)
    base, params = principled_table(snapshot([], [], [broken]))
    assert np.isfinite(base).all() and np.isfinite(params).all()
    np.testing.assert_allclose(params[0], [0.0, 1.0, 0.5])  # metallic 0, level clipped, rough ½

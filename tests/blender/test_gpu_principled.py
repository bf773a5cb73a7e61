"""render/shaders/principled.glsl (via render/gpu_principled.py) against the numpy model
voxgi_addon/gi/principled.py on random inputs (docs/gi_pipeline.md "Principled materials")."""
import numpy as np


def random_inputs(n=4096, seed=3):
    rng = np.random.default_rng(seed)

    def hemisphere(normal):
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.where(np.sum(d * normal, axis=1, keepdims=True) < 0, -d, d)

    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    view, light = hemisphere(normal), hemisphere(normal)
    # Some lights below the surface and some mirror-like and exactly-0.5 inputs.
    light[: n // 16] *= -1.0
    base = rng.uniform(0.0, 1.0, (n, 3))
    metallic = rng.choice([0.0, 1.0, 0.3, 0.7], n)
    level = np.where(rng.random(n) < 0.3, 0.5, rng.uniform(0.0, 1.0, n))
    level[:32] = 0.0
    roughness = np.where(rng.random(n) < 0.05, 0.0, rng.uniform(0.02, 1.0, n))
    irradiance = rng.uniform(0.5, 3.0, (n, 3))
    return base, metallic, level, roughness, normal, view, light, irradiance


def close(gpu, reference, floor):
    """Per component |gpu − numpy| ≤ 1% of numpy + ``floor``."""
    return np.abs(gpu - reference) <= 0.01 * np.abs(reference) + floor


def test_glsl_principled_equals_numpy(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_principled import evaluate
    from voxgi.voxgi_addon.gi import principled

    ready, why = ensure_gpu_context()
    assert ready, why
    base, metallic, level, roughness, normal, view, light, irradiance = random_inputs()
    got = evaluate(base, metallic, level, roughness, normal, view, light, irradiance)
    # The GPU receives float32 inputs: evaluate numpy on the same rounded values.
    f32 = [np.asarray(a, np.float32).astype(np.float64) for a in
           (base, metallic, level, roughness, normal, view, light, irradiance)]
    base, metallic, level, roughness, normal, view, light, irradiance = f32
    mu = np.sum(normal * view, axis=1)
    expected = {
        "diffuse_weight": principled.diffuse_weight(base, metallic, level, roughness, mu),
        "glossy_color": principled.glossy_color(base, metallic, level, roughness, mu),
        "glossy_reflectance": principled.glossy_reflectance(base, metallic, level, roughness,
                                                            normal, view, light),
        "outgoing_radiance": principled.outgoing_radiance(base, metallic, level, roughness,
                                                          normal, view, light, irradiance),
    }
    for name, reference in expected.items():
        ok = close(got[name], reference, 1e-5 * max(1.0, np.abs(reference).max()))
        print(f"{name}: {ok.mean():.5f} within 1%, max |d| {np.abs(got[name] - reference).max():.3g}")
        assert ok.mean() >= 0.999, name
        assert np.isfinite(got[name]).all(), name
    # The inputs exercise every branch: no glossy for level 0 dielectrics, none for lights
    # below the surface, and some glossy highlights well above the floor.
    assert np.all(got["glossy_reflectance"][: len(light) // 16] == 0.0)
    assert (expected["glossy_reflectance"] > 1.0).any()

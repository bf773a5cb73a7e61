"""render/shaders/ltc.glsl (via render/gpu_ltc.py) against the numpy LTC integrals of
voxgi_addon/gi/ltc.py on random points, views, roughnesses and triangles
(docs/gi_pipeline.md "LTC: the glossy lobe over polygons")."""
import numpy as np


def random_inputs(n=4096, seed=5):
    rng = np.random.default_rng(seed)

    def unit(x):
        return x / np.linalg.norm(x, axis=-1, keepdims=True)

    normal = unit(rng.normal(size=(n, 3)))
    view = unit(rng.normal(size=(n, 3)))
    view = np.where(np.sum(view * normal, axis=1, keepdims=True) < 0, -view, view)
    view[: n // 32] *= -1.0                     # some views below the surface: 0
    view[n // 32: n // 16] = normal[n // 32: n // 16]  # normal incidence: the fallback frame
    p = rng.normal(size=(n, 3))
    roughness = rng.uniform(0.0, 1.0, n)
    roughness[: n // 8] = rng.uniform(0.02, 0.15, n // 8)
    # triangles around the point at distances 0.3-5, half of them across or below the horizon
    centre = unit(rng.normal(size=(n, 3))) * rng.uniform(0.3, 5.0, (n, 1))
    corners = p[:, None] + centre[:, None] + rng.normal(size=(n, 3, 3)) * rng.uniform(0.05, 2.0, (n, 1, 1))
    return p, normal, view, roughness, corners


def test_glsl_ltc_equals_numpy(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_ltc import evaluate
    from voxgi.voxgi_addon.gi import ltc

    ready, why = ensure_gpu_context()
    assert ready, why
    p, n, v, roughness, corners = random_inputs()
    got = evaluate(p, n, v, roughness, corners)
    # The GPU receives float32 inputs: evaluate numpy on the same rounded values, per point.
    p, n, v, roughness, corners = [np.asarray(a, np.float32).astype(np.float64)
                                   for a in (p, n, v, roughness, corners)]
    expected = np.array([ltc.ltc_polygon_integral(p[i], n[i], v[i], roughness[i], corners[i:i + 1])[0, 0]
                         for i in range(len(p))])
    diff = np.abs(got - expected)
    print(f"max |GLSL - numpy| {diff.max():.3g}, mean {diff.mean():.3g}; "
          f"{(expected > 0.01).mean():.2f} of the triangles hold > 1% of the lobe")
    assert np.isfinite(got).all()
    assert diff.max() <= 1e-3
    assert np.all(got[: len(p) // 32] == 0.0)
    assert (expected > 0.1).mean() > 0.05

"""Sparse Gathers (``preview.sparse_gather``, docs/gi_pipeline.md "Gathers at fewer points"):
the diffuse gather traces one cell in four where surfaces are smooth and every cell where they
meet, the à-trous filter's first pass filling the others; both tracers plan it alike
(their agreement: test_multibounce.test_numpy_and_gpu_previews_agree[sparse]).
"""
from __future__ import annotations

import json
import pathlib

import bounce_scenes
import bpy
import numpy as np
from test_multibounce import preview, relative_l1

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "bounce_refs"


def test_sparse_gathers_trace_fewer_points_and_stay_near_cycles(voxgi, tmp_path, monkeypatch):
    """The Cornell box at 160 × 120 (Bounces follow Cycles): with Sparse Gathers the diffuse
    gather traces at most a third of its cells (counted), every cell still lit, and the
    preview stays within the scene's limits against Cycles (tests/data/bounce_refs) and close
    to the dense gather's image."""
    from voxgi.render import gpu_preview

    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    scene.voxgi.bounce_source = "CYCLES"
    dense = preview(tmp_path, scene, 160, 120)
    traced = []
    plan = gpu_preview.sparse_plan
    monkeypatch.setattr(gpu_preview, "sparse_plan",
                        lambda valid, *a: traced.append((plan(valid, *a), valid)) or traced[-1][0])
    scene.voxgi.sparse_gathers = True
    sparse = preview(tmp_path, scene, 160, 120)
    (cells, valid), = traced
    assert cells.sum() <= valid.sum() / 3, (cells.sum(), valid.sum())
    with np.load(REFS / "cornell_box.npz") as data:
        reference = {key: data[key].astype(np.float64) for key in data.files}
    mask = reference["Alpha"] > 0.5
    limits = json.loads((REFS / "limits.json").read_text())["cornell_box"]
    assert (sparse["Diffuse Indirect"][mask].max(axis=-1) > 0.0).all()  # no hole left dark
    for name, limit in limits.items():
        if name in sparse:
            assert relative_l1(sparse[name], reference[name], mask) <= limit, name
    assert relative_l1(sparse["Combined"], dense["Combined"], mask) <= 0.03


def test_f12s_spikes_are_traced_again_on_the_gpu(voxgi, tmp_path, monkeypatch):
    """The emissive room at 160 × 120: F12's GPU gather traces its brightest cells again with
    SPIKE_RAYS × the rays (``sparse_gather.retrace_spikes``, docs/gi_pipeline.md "Spikes traced
    again"): each read back in its row, merged with its first estimate by their rays, and the
    brightest comes out dimmer. Its bounce hits now take each picked emitter's exact light
    ("Emitters at bounce hits"), so no cell reads SPIKE × its neighbours any more (the rays into
    the lit slot over the panel did): the test picks the cells at 2 × theirs (5 of 2,500)."""
    from voxgi.voxgi_addon.preview import sparse_gather

    scene = bpy.context.scene
    bounce_scenes.build("emissive_room", scene)
    scene.voxgi.bounce_source = "CYCLES"
    seen = []
    retrace = sparse_gather.retrace_spikes

    def recorded(traced, values, variance, settings, trace):
        def traced_again(cells, more):
            out = trace(cells, more)
            seen.append((cells.copy(), more, settings, values[cells].copy(),
                         np.asarray(out[0], np.float64).copy()))
            return out
        again = retrace(traced, values, variance, settings, traced_again)
        if seen:
            seen[-1] = seen[-1] + (values[again].copy(),)
        return again

    monkeypatch.setattr(sparse_gather, "retrace_spikes", recorded)
    monkeypatch.setattr(sparse_gather, "SPIKE", 2.0)
    ours = preview(tmp_path, scene, 160, 120)
    (cells, more, settings, first, second, merged), = seen
    assert 0 < cells.sum() < 0.01 * cells.size  # a few cells, not the image
    assert more.rays == sparse_gather.SPIKE_RAYS * settings.rays and more.seed == settings.seed + 1
    assert np.isfinite(second).all() and (second[:, :3] >= 0.0).all()
    share = 1.0 / (1 + sparse_gather.SPIKE_RAYS)
    np.testing.assert_allclose(merged[:, :4], share * first[:, :4] + (1 - share) * second[:, :4],
                               rtol=1e-5, atol=1e-6)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    assert (merged[:, :3] @ luminance).max() < (first[:, :3] @ luminance).max()
    assert np.isfinite(ours["Combined"]).all()

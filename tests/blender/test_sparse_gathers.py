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

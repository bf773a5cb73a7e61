"""Diffuse Indirect from the baked light probes instead of cone tracing (docs/probes.md
"Query"), for the preview pipeline (F12 and ``voxgi.render_preview``).

The passes come from the usual tracer; this replaces their ``Diffuse Indirect`` at every pixel
that sees a surface by the probes' irradiance / π at the pixel's exact hit point and shading
normal (``scene.raycast.primary_visibility``, the numpy tracer's visibility), and ``Combined``
by the same change times ``Diffuse Color`` (Combined = albedo · (direct + indirect) + …).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..blender import probe_store
from ..blender.settings import cone_settings
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.probes.query import query_grids
from ..voxgi_addon.scene.geometry import world_triangles
from ..voxgi_addon.scene.raycast import primary_visibility


def apply_probe_indirect(scene, snapshot, passes, width, height):
    """Replace ``passes``' Diffuse Indirect (and Combined) in place; returns (seconds, line)."""
    grids = probe_store.load_grids(scene)
    if not grids:
        raise VoxGIError("Indirect Light is set to Light Probes but the scene has no baked probes: "
                         "run Bake Probes (voxgi.bake_probes) first")
    start = time.perf_counter()
    seen = primary_visibility(world_triangles(snapshot), snapshot.camera, width, height)
    hit = seen.hit
    indirect = np.zeros((height, width, 3), np.float32)
    indirect[hit] = query_grids(grids, seen.position[hit], seen.normal[hit],
                                use_masks=scene.voxgi.probe_masks) / math.pi
    indirect *= cone_settings(scene.voxgi).gi_intensity
    old = passes["Diffuse Indirect"]
    passes["Combined"] = passes["Combined"] + passes["Diffuse Color"] * (indirect - old)
    passes["Diffuse Indirect"] = indirect
    probes = sum(len(g.positions) for g in grids)
    return time.perf_counter() - start, ("INFO", f"VoxGI: Diffuse Indirect from {probes} light probes")

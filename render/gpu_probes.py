"""Probe bake on the GPU through the voxel octree (docs/probes.md "GPU bake").

``gpu_probe_sh``: pass 1 (``shaders/probe_bake.glsl``) marches one narrow cone per (probe,
direction) pair through the octree atlas with the preview's march (``cone_common.glsl``); pass 2
(``shaders/probe_sh.glsl``) projects each probe's radiance on SH L2 — the port of
``voxgi_addon.probes.octree_bake.octree_probe_sh`` (the reference, tested equal within 1 %).
``bake_grid_from_octree``: the whole bake with that radiance stage (placement, validity and masks
exact, as ever, and the world's light straight at the probe too: ``probes.direct``), the numpy
reference when no GPU context can be had. Main thread only.
"""
from __future__ import annotations

import math

import numpy as np

from ..blender.session import scene_session
from ..blender.settings import cone_settings, gi_settings
from ..voxgi_addon.gi.update import update_gi
from ..voxgi_addon.gi.world_light import world_light
from ..voxgi_addon.probes.bake import bake_probe_grid
from ..voxgi_addon.probes.octree_bake import START_OFFSET, cone_half_angle, octree_probe_sh
from . import gpu_context

ROW = 4096        # texels per row of the position and radiance images
SH_PER_ROW = 64   # probes per row of the SH image (9 texels each)


def gpu_probe_sh(volume, positions, directions, world, cones) -> np.ndarray:
    """(P, 9, 3) float64 SH of each probe's radiance through ``volume`` (a ``GPUVolume``)."""
    from .gpu_tracer import dispatch, read_texture
    from .gpu_volume import float_texture

    p = np.asarray(positions, np.float32).reshape(-1, 3)
    d = np.asarray(directions, np.float32).reshape(-1, 3)
    count, n = len(p), len(d)
    if count == 0:
        return np.zeros((0, 9, 3))
    width = min(ROW, count)
    rows = math.ceil(count / width)
    pos = np.zeros((rows * width, 4), np.float32)
    pos[:count, :3] = p
    pos_tex = float_texture(pos, (width, rows))
    dirs = np.zeros((n, 4), np.float32)
    dirs[:, :3] = d
    dir_tex = float_texture(dirs, (n, 1))
    pairs = count * n
    w = min(ROW, pairs)
    h = math.ceil(pairs / w)
    sampling = (n, count, START_OFFSET, math.tan(cone_half_angle(n)))
    w_rgb = np.asarray(world, np.float64)[:3]
    radiance = dispatch("probe_bake", volume, {"probe_positions": pos_tex, "probe_dirs": dir_tex},
                        w, h, {"sampling": sampling, "world": (*w_rgb, cones.max_distance)})
    sh_rows = math.ceil(count / SH_PER_ROW)
    out = dispatch("probe_sh", volume, {"probe_radiance": radiance, "probe_dirs": dir_tex},
                   9 * SH_PER_ROW, sh_rows, {"sampling": (n, count, w, 0)})
    values = read_texture(out).reshape(sh_rows * SH_PER_ROW, 9, 4)
    return values[:count, :, :3].astype(np.float64)


def octree_state(context, scene, snapshot):
    """The scene's last GI update, or a new one (voxelizing if needed)."""
    session = scene_session(scene.name_full)
    if session.gi_state is None:
        from .pipeline import caches_for
        session.gi_state = update_gi(snapshot, caches_for(context, snapshot, scene),
                                     gi_settings(scene.voxgi))
    return session.gi_state


def octree_world(snapshot) -> np.ndarray:
    """What an open cone of the octree bakes sees: nothing when the world is a light (its map
    sheds light: the bake adds its light at the probe exactly, ``probes.bake.direct_probe_sh``),
    else the world's colour × strength."""
    if world_light(snapshot.world) is not None:
        return np.zeros(3)
    return np.asarray(snapshot.world.color, np.float64)[:3] * float(snapshot.world.strength)


def octree_sh_function(context, scene, snapshot):
    """(sh_fn for ``bake_probe_grid``, 'GPU' or 'numpy')."""
    state = octree_state(context, scene, snapshot)
    cones = cone_settings(scene.voxgi)
    world = octree_world(snapshot)
    ready, _ = gpu_context.ensure_gpu_context()
    if ready:
        from .gpu_volume import GPUVolume
        session = scene_session(scene.name_full)
        session.gpu_volume = session.gpu_volume or GPUVolume()
        volume = session.gpu_volume
        volume.update(state.octree, cones)
        return (lambda positions, dirs: gpu_probe_sh(volume, positions, dirs, world, cones)), "GPU"
    return (lambda positions, dirs: octree_probe_sh(state.octree, positions, dirs, cones, world)), "numpy"


def bake_grid_from_octree(context, scene, snapshot, settings, box, name):
    """``bake_probe_grid`` with the octree radiance stage (GPU when possible)."""
    sh_fn, _ = octree_sh_function(context, scene, snapshot)
    return bake_probe_grid(snapshot, settings, box, name=name, sh_fn=sh_fn)

"""The baked light probes in the 3D view (docs/probes.md): a ``SpaceView3D`` draw handler the
add-on owns (added on register, removed on unregister).

Probes are small spheres whose vertices are coloured by the probe's SH irradiance for the
vertex normal (irradiance / π: what a white diffuse surface facing that way would show);
disabled probes are grey. Active volumes are wire boxes. With ``Scene.voxgi.probe_selected``
≥ 0, that probe's position gets a cross and the centres of the sub-volumes its masks let it light
are drawn as green points (blocked ones as small red points), in every volume it belongs to.
Batches are built once per set of grids and settings and cached.
"""
from __future__ import annotations

import atexit
import math

import bpy
import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ..blender import probe_store
from ..voxgi_addon.probes.grid import CORNER_OFFSETS
from ..voxgi_addon.probes.placement import SUBDIVISIONS
from ..voxgi_addon.probes.sh import COSINE_LOBE, sh_basis

_cache: dict[str, object] = {}
_handle = None
_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]


def _unit_sphere(rings: int = 6, segments: int = 10):
    """(V, 3) unit vertices and (T, 3) triangles of a UV sphere."""
    theta = np.linspace(0, math.pi, rings + 1)
    phi = np.linspace(0, 2 * math.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    tris = []
    for r in range(rings):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            c, d = a + segments, b + segments
            tris += [(a, c, d), (a, d, b)]
    return v, np.array(tris, np.int64)


def probe_sphere_geometry(grids, radius: float):
    """Positions (N, 3) and RGBA colours (N, 4) float32 of every probe sphere's triangle corners."""
    unit, tris = _unit_sphere()
    corner_dirs = unit[tris.ravel()]  # (K, 3): each triangle corner of one sphere
    basis = (sh_basis(corner_dirs) * COSINE_LOBE).astype(np.float32)  # (K, 9)
    positions, colours = [], []
    for g in grids:
        sh = np.asarray(g.sh, np.float32)  # (P, 9, 3)
        colour = np.einsum("kj,pjc->pkc", basis, sh) / math.pi  # (P, K, 3)
        colour = np.clip(colour, 0.0, 1.0)
        disabled = ~np.asarray(g.enabled)
        colour[disabled] = 0.35
        alpha = np.ones(colour.shape[:2] + (1,), np.float32)
        positions.append((np.asarray(g.positions, np.float32)[:, None, :] + radius * corner_dirs[None]).reshape(-1, 3))
        colours.append(np.concatenate([colour, alpha], axis=2).reshape(-1, 4))
    if not positions:
        return np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32)
    return np.concatenate(positions).astype(np.float32), np.concatenate(colours).astype(np.float32)


def volume_lines(grids) -> np.ndarray:
    """(2E, 3) float32 line-segment end points of every active volume's box."""
    out = []
    for g in grids:
        cells = np.asarray(g.volume_cells, np.int64)
        d = g.dims
        xyz = np.stack([cells % d[0], (cells // d[0]) % d[1], cells // (d[0] * d[1])], axis=1)
        corners = g.origin + (xyz[:, None, :] + CORNER_OFFSETS[None]) * g.volume_size  # (V, 8, 3)
        out.append(corners[:, np.array(_EDGES).ravel()].reshape(-1, 3))
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, 3), np.float32)


def selected_subvolumes(grids, probe: int):
    """(probe position or None, lit sub-volume centres (N, 3), blocked centres (M, 3)) of probe
    ``probe`` of the first grid that has it, over every volume the probe belongs to."""
    for g in grids:
        if not 0 <= probe < len(g.positions):
            probe -= len(g.positions)
            continue
        rows, corners = np.nonzero(np.asarray(g.volume_probes, np.int64) == probe)
        cells = np.asarray(g.volume_cells, np.int64)[rows]
        d = g.dims
        xyz = np.stack([cells % d[0], (cells // d[0]) % d[1], cells // (d[0] * d[1])], axis=1)
        bits = np.arange(64)
        sub = np.stack([bits % 4, (bits // 4) % 4, bits // 16], axis=1)
        centres = g.origin + (xyz[:, None, :] + (sub[None] + 0.5) / SUBDIVISIONS) * g.volume_size
        masks = np.asarray(g.volume_masks, np.uint64)[rows, corners]
        lit = ((masks[:, None] >> bits.astype(np.uint64)[None]) & np.uint64(1)).astype(bool)
        return (np.asarray(g.positions[probe], np.float64), centres[lit].astype(np.float32),
                centres[~lit].astype(np.float32))
    return None, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)


def _batches(grids, settings):
    key = (id(grids), len(grids), round(settings.probe_display_size, 6), settings.probe_selected)
    if _cache.get("key") == key:
        return _cache["batches"]
    smooth = gpu.shader.from_builtin("SMOOTH_COLOR")
    flat = gpu.shader.from_builtin("UNIFORM_COLOR")
    pos, col = probe_sphere_geometry(grids, settings.probe_display_size)
    batches = [(smooth, batch_for_shader(smooth, "TRIS", {"pos": pos, "color": col}), None, 0)]
    batches.append((flat, batch_for_shader(flat, "LINES", {"pos": volume_lines(grids)}),
                    (0.3, 0.7, 0.8, 0.6), 0))
    centre, lit, blocked = selected_subvolumes(grids, settings.probe_selected)
    if centre is not None:
        r = 2 * settings.probe_display_size
        cross = np.array([centre + s * r * a for a in np.eye(3) for s in (-1, 1)], np.float32)
        batches.append((flat, batch_for_shader(flat, "LINES", {"pos": cross}), (1, 1, 0, 1), 0))
        batches.append((flat, batch_for_shader(flat, "POINTS", {"pos": lit}), (0.1, 1, 0.2, 1), 6))
        batches.append((flat, batch_for_shader(flat, "POINTS", {"pos": blocked}), (1, 0.1, 0.1, 1), 3))
    _cache.update(key=key, batches=batches, grids=grids)
    return batches


def draw_grids(scene) -> None:
    """Draw ``scene``'s probes with the current gpu matrices (the view's, or a test's)."""
    settings = scene.voxgi
    grids = probe_store.load_grids(scene)
    if not settings.probe_display or not grids:
        return
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    for shader, batch, colour, point_size in _batches(grids, settings):
        shader.bind()
        if colour is not None:
            shader.uniform_float("color", colour)
        if point_size:
            gpu.state.point_size_set(point_size)
        batch.draw(shader)
    gpu.state.point_size_set(1.0)
    gpu.state.depth_mask_set(False)
    gpu.state.depth_test_set("NONE")


def _draw_handler() -> None:
    scene = bpy.context.scene
    if scene is not None and hasattr(scene, "voxgi"):
        draw_grids(scene)


def release() -> None:
    """Drop the cached batches (GPU buffers; docs/gi_pipeline.md "GPU resources at exit")."""
    _cache.clear()


classes = ()


def register() -> None:
    global _handle
    _handle = bpy.types.SpaceView3D.draw_handler_add(_draw_handler, (), "WINDOW", "POST_VIEW")
    atexit.unregister(release)
    atexit.register(release)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    atexit.unregister(release)
    release()

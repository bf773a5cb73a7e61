"""Cycles ground truth and VoxGI's exact direct light for the Blender tests.

The rendering harness itself lives in ``tools/cycles_passes.py`` (not shipped in the extension;
``tools/`` scripts use it too); this module adds what the tests compare it with. Imports of the
add-on happen inside the functions: ``voxgi`` is importable once the session fixture ran.
"""
from __future__ import annotations

import pathlib
import sys

import bpy
import numpy as np


def _reference():
    tools = str(pathlib.Path(__file__).resolve().parents[2] / "tools")
    if tools not in sys.path:
        sys.path.insert(0, tools)
    import cycles_passes

    return cycles_passes


def render_cycles_passes(scene, width, height, samples, diffuse_bounces=1, ao_distance=None, seed=0, **options):
    """See ``tools/cycles_passes.py: render_cycles_passes``."""
    return _reference().render_cycles_passes(scene, width, height, samples, diffuse_bounces,
                                             ao_distance, seed, **options)


def relative_l1(ours, reference, mask):
    return _reference().relative_l1(ours, reference, mask)


def coverage_agreement(ours, passes):
    return _reference().coverage_agreement(ours, passes)


def snapshot_triangles(scene):
    """(SceneSnapshot, SceneTriangles) of ``scene`` at its current frame."""
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    depsgraph = bpy.context.evaluated_depsgraph_get()
    snapshot = take_snapshot(scene, depsgraph)
    return snapshot, world_triangles(snapshot)


def exact_diffuse_direct(scene, width, height, samples=16, seed=0):
    """VoxGI's primary visibility + ``diffuse_direct`` of the scene camera.

    Returns (Diffuse Direct (H, W, 3) float32 with 0 on the background, PrimaryHits).
    """
    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
    from voxgi.voxgi_addon.scene.raycast import primary_visibility

    snapshot, tris = snapshot_triangles(scene)
    primary = primary_visibility(tris, snapshot.camera, width, height)
    image = np.zeros((height, width, 3), dtype=np.float32)
    image[primary.hit] = diffuse_direct(primary.position[primary.hit], primary.normal[primary.hit],
                                        snapshot.lights, tris, samples=samples, seed=seed)
    return image, primary

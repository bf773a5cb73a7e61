"""Probe bakes carry the preview's bounces (issue 20 point 2): with Bounces above 1 each probe
ray's hit also reflects the radiance cache's light, so the probes (and the files they are
exported to) hold the multi-bounce light the preview shows."""
from __future__ import annotations

import bounce_scenes
import bpy
import numpy as np

INSIDE = ((-0.9, -0.9, 0.1), (0.9, 0.9, 1.9))  # the box's interior (its front is open)


def test_probes_bake_the_bounces_the_preview_shows(voxgi):
    from voxgi.blender.settings import probe_settings
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.voxgi_addon.probes.bake import ProbeSettings, bake_probe_grid
    from voxgi.voxgi_addon.probes.sh import irradiance

    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    snapshot, _ = snapshot_or_error(bpy.context, bpy.context.evaluated_depsgraph_get())
    mean = {}
    for bounces in (1, 3):
        settings = ProbeSettings(resolution=2, directions=64, radiance_factor=1,
                                 direct_samples=16, bounces=bounces)
        grid = bake_probe_grid(snapshot, settings, box=INSIDE).grid
        up = np.tile([0.0, 0.0, 1.0], (len(grid.sh), 1))
        mean[bounces] = float(np.mean([irradiance(c, n) for c, n in zip(grid.sh, up)]))
    print(f"mean upward irradiance: one bounce {mean[1]:.4f}, three {mean[3]:.4f}")
    # the box's area light faces down: the ceiling above the probes is lit only from the
    # second bounce on, so their upward irradiance grows most (about 3x measured)
    assert mean[3] > 1.1 * mean[1] > 0.0
    # the bake takes the scene's Bounces (Follow Cycles: its Diffuse bounces, 4 by default)
    scene.voxgi.bounce_source = "CYCLES"
    assert probe_settings(scene.voxgi).bounces == min(scene.cycles.diffuse_bounces,
                                                      scene.cycles.max_bounces)

"""Light leaking through a thin wall (the closed-room test of docs/gi_pipeline.md).

The issue's target: the dark side's Diffuse Indirect stays below 2% of the lit side's mean
(a 2 cm wall in 7 cm voxels). Measured about 1.3% (GPU and numpy tracers): anisotropic voxels
with per-axis extinction and one-sided leaves (4.3%; isotropic: about 20%), plus light cones
that weigh each face's colour by its share of the optical depth, read colour one level finer
than occlusion and attenuate what lies behind a sample with exponent 1.5
(``conetrace.ConeSettings``).
"""
import bpy
import numpy as np
import scenes

WIDTH, HEIGHT = 128, 64
ISSUE_BOUND = 0.02


def test_thin_wall_keeps_most_light_on_its_side(voxgi, tmp_path):
    from voxgi.voxgi_addon.files.exr import read_exr

    scene = bpy.context.scene
    scenes.build_thin_wall_room(scene)
    scene.voxgi.span_mode = "MANUAL"  # the bounds were tuned at this span (Auto picks 0.0625 m here)
    scene.voxgi.base_span = 0.07
    scene.voxgi.grid_resolution = "64"
    path = tmp_path / "room.exr"
    assert bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=WIDTH,
                                        resolution_y=HEIGHT) == {"FINISHED"}
    channels = read_exr(path)
    indirect = np.mean([channels[f"Diffuse Indirect.{c}"] for c in "RGB"], axis=0)
    direct = np.mean([channels[f"Diffuse Direct.{c}"] for c in "RGB"], axis=0)
    lit, dark = scenes.thin_wall_side_masks(WIDTH, HEIGHT)
    assert direct[dark].max() == 0.0  # the wall blocks all direct light
    lit_mean = indirect[lit].mean()
    assert lit_mean > 0.1
    ratio = indirect[dark].max() / lit_mean
    print(f"thin wall: dark-side max / lit-side mean Diffuse Indirect = {ratio:.3f}")
    assert ratio <= ISSUE_BOUND

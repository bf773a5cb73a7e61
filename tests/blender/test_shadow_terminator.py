"""Cycles' shadow terminator offset (voxgi_addon/gi/terminator.py, bvh_lights.glsl
``shadow_hit``): a low-poly sphere shaded smooth, half lit by a sun, has the terminator band
Cycles renders — its shadow rays leave from the smooth surface, not the faceted one."""
from __future__ import annotations

import math

import bpy
import numpy as np
import scenes
from cycles_reference import render_cycles_passes
from mathutils import Vector

WIDTH, HEIGHT = 64, 48


def _sphere_scene():
    scene = bpy.context.scene
    mesh = bpy.data.meshes.new("Low poly")
    import bmesh

    shape = bmesh.new()
    bmesh.ops.create_uvsphere(shape, u_segments=8, v_segments=5, radius=1.0)
    shape.to_mesh(mesh)
    shape.free()
    mesh.shade_smooth()
    sphere = bpy.data.objects.new("Low poly", mesh)
    scene.collection.objects.link(sphere)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, math.radians(1.0)
    sun.rotation_euler = Vector((-1.0, 0.2, -0.3)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    scenes.camera_looking_at((0.0, -4.0, 0.0), scene=scene)
    scenes.uniform_world((0.0, 0.0, 0.0), scene, "Black")
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 1
    bpy.context.view_layer.update()
    return scene


def test_a_smooth_low_poly_spheres_terminator_is_lit_as_in_cycles(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.pipeline import render_scene_passes

    ready, why = ensure_gpu_context()
    assert ready, why
    scene = _sphere_scene()
    ours, _ = render_scene_passes(bpy.context, scene, None, WIDTH, HEIGHT)
    cycles = render_cycles_passes(scene, WIDTH, HEIGHT, 256, seed=1)
    seen = cycles["Alpha"] > 0.5
    light = {name: (np.asarray(p["Diffuse Direct"], np.float64)[..., :3]
                    * np.asarray(p["Diffuse Color"], np.float64)[..., :3]).sum(axis=-1)
             for name, p in (("ours", ours), ("cycles", cycles))}
    ratio = light["ours"][seen].sum() / light["cycles"][seen].sum()
    # the lit pixels within a band of the terminator: where the lift shows
    band = seen & (light["cycles"] > 0.0) & (light["cycles"] < 0.35 * light["cycles"].max())
    band_ratio = light["ours"][band].sum() / light["cycles"][band].sum()
    print(f"Diffuse Direct over the sphere {ratio:.3f} of Cycles', in the terminator band "
          f"({band.sum()} px) {band_ratio:.3f}")
    # (shadow rays from the facets instead read 0.964 over the sphere, 0.773 in the band)
    assert band.sum() > 20
    assert abs(ratio - 1.0) < 0.015
    assert abs(band_ratio - 1.0) < 0.05

"""Kernels built for what the scene has (render/gpu_bvh.py ``bvh_shader``; docs/gi_pipeline.md
"Where a preview's time goes"): a scene without cut-outs, textures, triangles hidden from some
rays or some kind of light traces with kernels that leave that code out (llvmpipe pays for a
branch's code at every triangle test and hit whether a lane takes it or not: the cut-out test
alone made every ray 3–4× slower), and its passes are exactly those of the kernels with every
feature; a scene with cut-outs or textures gets the kernels that read them.
"""
from __future__ import annotations

import bpy
import cutout_scenes
import light_scenes
import numpy as np
import scenes
from test_gpu_scene import HEIGHT, WIDTH, gpu_ready, render, snapshot_now


def traced_variants(fn, every_feature=False):
    """(result of ``fn``, the (kernel, cut-outs, textures, absent lights, hidden triangles)
    variants it dispatched); every_feature: build every kernel with all the code."""
    from voxgi.render import gpu_bvh

    original = gpu_bvh.bvh_shader
    used = set()

    def shader(kernel, cutouts=True, textures=True, absent=(), hidden=True):
        if every_feature:
            cutouts, textures, absent, hidden = True, True, (), True
        used.add((kernel, cutouts, textures, tuple(absent), hidden))
        return original(kernel, cutouts, textures, absent, hidden)

    gpu_bvh.bvh_shader = shader
    try:
        return fn(), used
    finally:
        gpu_bvh.bvh_shader = original


def fresh_render():
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene

    snapshot = snapshot_now()
    return render(snapshot, GPUScene(bvh=GPUBVH()), WIDTH, HEIGHT)


def gathers(used):
    return {v for v in used if v[0] == "bvh_gather"}


def test_a_plain_scene_traces_lean_kernels_and_the_same_image(voxgi):
    """The test Cornell box (an area light, no textures, no cut-outs, no world light, no
    metal): its gathers run the variant without cut-outs, textures, sun, point lights, world,
    emitters, a metal's glossy lobe over an area lamp or its lamp picks by that lobe, and every
    pass equals the one of the kernels with all the code."""
    gpu_ready()
    scenes.build_test_cornell_box(bpy.context.scene, light="AREA")
    lean, used = traced_variants(fresh_render)
    full, used_full = traced_variants(fresh_render, every_feature=True)
    assert gathers(used) == {("bvh_gather", False, False,
                              ("EMITTERS", "METALS", "METAL_AREA", "POINT", "SUN", "WORLD"),
                              False)}
    assert gathers(used_full) == {("bvh_gather", True, True, (), True)}
    for name, image in full.items():
        assert np.array_equal(lean[name], image), name


def test_a_scene_with_emitters_keeps_their_code(voxgi):
    """The room lit by a spot and emissive surfaces: its gathers keep the point-light and
    emitter code, leave the sun, area lights and world out, and give the same passes."""
    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    lean, used = traced_variants(fresh_render)
    full, _ = traced_variants(fresh_render, every_feature=True)
    absent = {v[3] for v in gathers(used)}
    assert absent == {("AREA", "METALS", "SUN", "WORLD")}
    for name, image in full.items():
        assert np.allclose(lean[name], image, rtol=0, atol=1e-6 * max(np.abs(image).max(), 1)), \
            name


def test_a_metal_under_an_area_lamp_keeps_its_lobe_over_the_lamp(voxgi):
    """The room of metals (an area lamp, a point lamp, steel, copper and gold): its gathers
    keep the metal hits' lobe over the area lamp (bvh_shade.glsl, gpu_bvh.has_metals) and give
    the passes of the kernels with every feature; built without that code they give another
    Glossy Indirect (the lobe toward one direction), so the code runs. With its metals turned
    dielectric the room's gathers leave the code out, and the metal hits' lamp picks by their
    lobe too."""
    from voxgi.render import gpu_bvh

    gpu_ready()
    light_scenes.build("metal_room", bpy.context.scene)
    lean, used = traced_variants(fresh_render)
    full, _ = traced_variants(fresh_render, every_feature=True)
    assert {v[3] for v in gathers(used)} == {("EMITTERS", "SUN", "WORLD")}
    for name, image in full.items():
        assert np.allclose(lean[name], image, rtol=0, atol=1e-6 * max(np.abs(image).max(), 1)), \
            name
    original = gpu_bvh.bvh_shader
    gpu_bvh.bvh_shader = lambda kernel, cutouts=True, textures=True, absent=(), hidden=True: \
        original(kernel, cutouts, textures, tuple(sorted(set(absent) | {"METAL_AREA"})), hidden)
    try:
        one_direction = fresh_render()
    finally:
        gpu_bvh.bvh_shader = original
    change = np.abs(one_direction["Glossy Indirect"] - lean["Glossy Indirect"]).sum()
    print("one direction changes Glossy Indirect by", change / np.abs(lean["Glossy Indirect"]).sum())
    assert change > 0.02 * np.abs(lean["Glossy Indirect"]).sum()
    for material in bpy.data.materials:
        bsdf = material.node_tree.nodes.get("Principled BSDF") if material.node_tree else None
        if bsdf is not None:
            bsdf.inputs["Metallic"].default_value = 0.0
    _, used = traced_variants(fresh_render)
    assert {v[3] for v in gathers(used)} == {("EMITTERS", "METALS", "METAL_AREA", "SUN", "WORLD")}


def test_cut_outs_get_the_kernels_that_read_their_alpha(voxgi):
    """The fence cards (image-textured cut-outs): every BVH kernel is built with the cut-out
    test and the texture code, and the slats still let light through as before."""
    gpu_ready()
    cutout_scenes.build("fence_cards", bpy.context.scene)
    lean, used = traced_variants(fresh_render)
    assert used and all(cutouts and textures for _, cutouts, textures, _, _ in used)
    full, _ = traced_variants(fresh_render, every_feature=True)
    for name, image in full.items():
        assert np.array_equal(lean[name], image), name


def test_ray_visibility_keeps_the_hidden_test(voxgi):
    """A wall hidden from shadow rays (Object › Visibility): the kernels keep the hidden-triangle
    test (so the wall casts no shadow), the plain box leaves it out."""
    gpu_ready()
    scenes.build_test_cornell_box(bpy.context.scene, light="AREA")
    _, plain = traced_variants(fresh_render)
    wall = next(o for o in bpy.context.scene.objects if o.type == "MESH")
    wall.visible_shadow = False
    lean, used = traced_variants(fresh_render)
    assert all(not hidden for *_, hidden in plain)
    assert used and all(hidden for *_, hidden in used)
    full, _ = traced_variants(fresh_render, every_feature=True)
    for name, image in full.items():
        assert np.array_equal(lean[name], image), name

"""Alpha cut-outs (issue 22 point 2, acceptance (b)): the Alpha of a material — a value, an
image's alpha channel, or a node tree Cycles bakes — lets camera, bounce and shadow rays through
in proportion, per texel, on the GPU as in the numpy reference, against Cycles
(tests/data/cutout_refs, made by tools/make_cutout_references.py: one bounce of either kind,
Cycles' default transparent bounces and pixel filter)."""
from __future__ import annotations

import json
import pathlib

import bpy
import cutout_scenes
import numpy as np

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "cutout_refs"
PASSES = ("Combined", "Diffuse Color", "Diffuse Direct", "Diffuse Indirect")


def relative_l1(ours, reference, mask=None):
    if mask is None:
        mask = np.ones(reference.shape[:2], bool)
    return float(np.abs(ours[mask] - reference[mask]).sum() /
                 max(np.abs(reference[mask]).sum(), 1e-12))


def build(name="fence_cards"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cutout_scenes.build(name, scene)
    return scene


def preview(scene, tracer="AUTO", width=cutout_scenes.WIDTH, height=cutout_scenes.HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}, lines


def snapshot_now():
    from voxgi.blender.snapshot.scene import take_snapshot

    return take_snapshot(bpy.context.scene)


def fence_material(snapshot):
    return next(m for m in snapshot.materials if m.name == "Fence")


def test_base_color_and_alpha_come_from_one_rgba_image(voxgi):
    build()
    snapshot = snapshot_now()
    assert snapshot.warnings == ()  # no "renders opaque" note any more
    fence = fence_material(snapshot)
    assert fence.base_color_texture >= 0 and fence.alpha_texture == fence.base_color_texture
    texture = snapshot.textures[fence.alpha_texture]
    assert texture.pixels.shape == (cutout_scenes.FENCE_SIZE, cutout_scenes.FENCE_SIZE, 4)
    # alpha is linear whatever the colour space: the image's own 0 / 1
    np.testing.assert_array_equal(texture.pixels[..., 3], cutout_scenes.fence_pixels()[..., 3])
    plain = next(m for m in snapshot.materials if m.name == "Red Wall")
    assert plain.alpha == 1.0 and plain.alpha_texture == -1


def test_alpha_values_ignored_alpha_and_baked_alpha(voxgi):
    """An unlinked Alpha is a value; an image whose Alpha Mode is None is opaque (Cycles
    ignores its alpha); an Alpha from other nodes (a Checker Texture) is baked by Cycles into a
    texture's 4th channel."""
    build()
    tree = bpy.data.materials["Fence"].node_tree
    image_node = next(n for n in tree.nodes if n.type == "TEX_IMAGE")
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    bpy.data.images["Fence Image"].alpha_mode = "NONE"
    fence = fence_material(snapshot_now())
    assert fence.alpha == 1.0 and fence.alpha_texture == -1
    bpy.data.images["Fence Image"].alpha_mode = "STRAIGHT"
    tree.links.remove(bsdf.inputs["Alpha"].links[0])
    bsdf.inputs["Alpha"].default_value = 0.35
    fence = fence_material(snapshot_now())
    assert abs(fence.alpha - 0.35) < 1e-6 and fence.alpha_texture == -1
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (1.0, 1.0, 1.0, 1.0)
    checker.inputs["Color2"].default_value = (0.0, 0.0, 0.0, 1.0)
    tree.links.new(checker.outputs["Fac"], bsdf.inputs["Alpha"])
    snapshot = snapshot_now()
    fence = fence_material(snapshot)
    assert fence.alpha_texture >= 0 and fence.alpha_texture != fence.base_color_texture
    alpha = snapshot.textures[fence.alpha_texture].pixels[..., 3]
    assert 0.4 < (alpha > 0.99).mean() < 0.6 and 0.4 < (alpha < 0.01).mean() < 0.6
    assert image_node.image.name == "Fence Image"  # the user's tree is as it was


def test_gpu_rays_pass_cutouts_as_the_numpy_rays_do(voxgi):
    """The GLSL traversal (bvh_common.glsl + textures.glsl) counts a cut-out's hits as
    raycast does (the same hash of the float32 ray), closest and any hit."""
    from test_gpu_bvh import gpu_ready

    from voxgi.render.gpu_bvh import GPUBVH, trace_rays
    from voxgi.render.gpu_scene import GPUScene
    from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded

    build()
    snapshot = snapshot_now()
    gpu_ready()
    scene = GPUScene(GPUBVH()).update(snapshot)
    tris = scene.tris
    assert tris.textures.cutout.sum() == 4  # the two cards' triangles
    rng = np.random.default_rng(3)
    n = 6000
    # from in front of the cards towards them and the wall behind
    o = np.column_stack([rng.uniform(-2.5, 2.5, n), np.full(n, -2.0), rng.uniform(0.1, 1.7, n)])
    target = np.column_stack([rng.uniform(-2.5, 2.5, n), np.full(n, 1.5), rng.uniform(0.1, 1.7, n)])
    d = (target - o) / np.linalg.norm(target - o, axis=1, keepdims=True)
    o, d = o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64)
    t, tri, _, _ = trace_rays(scene.bvh, o, d, 1e-4, np.inf)
    rt, rtri, _, _ = closest_hits(tris, o, d, 1e-4)
    cards = np.flatnonzero(tris.textures.cutout)
    crossing = np.isin(rtri, cards) | (np.isfinite(rt) & ~np.isin(rtri, cards))
    assert crossing.all()
    on_card = np.isin(rtri, cards)
    assert 0.15 < on_card.mean() < 0.6  # some rays meet the wood, others pass the gaps
    same = tri == rtri
    assert same.mean() > 0.995, same.mean()  # float32 barycentrics at the slats' edges
    max_t = np.full(n, 3.0)
    blocked = trace_rays(scene.bvh, o, d, 0.0, max_t, any_hit=True)
    reference = occluded(tris, o, d, max_t)
    assert (blocked == reference).mean() > 0.995
    assert 0.1 < reference.mean() < 0.9


def stacked_veils(count, alpha, frame=False):
    """``count`` parallel cards of one Alpha value, 0.25 m apart along +y, a wall behind them;
    ``frame``: an opaque quad in the first card's plane over its half x < 0 (a wall about a
    pane, in the pane's own plane)."""
    import gi_scenes
    import texture_scenes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    veil = gi_scenes._material("Veil", (0.6, 0.6, 0.6))
    next(n for n in veil.node_tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Alpha"].default_value = alpha
    wall = gi_scenes._material("Wall", (0.5, 0.5, 0.5))
    for i in range(1 if frame else 0, count):
        y = 0.25 * i
        texture_scenes.quad(scene, f"Veil {i}", [(-2, y, 0), (2, y, 0), (2, y, 2), (-2, y, 2)], veil)
    back = 0.25 * count + 0.5
    if frame:  # the first card's half x < 0 again, opaque: its hits at the very same t
        half = [(-2, 0, 0), (0, 0, 0), (0, 0, 2), (-2, 0, 2)]
        texture_scenes.quad(scene, "Veil 0 left", half, veil)
        texture_scenes.quad(scene, "Veil 0 right", [(0, 0, 0), (2, 0, 0), (2, 0, 2), (0, 0, 2)], veil)
        gi_scenes._mesh(scene, "Frame", half, [(0, 1, 2, 3)], (wall,))
    gi_scenes._mesh(scene, "Wall", [(-3, back, -1), (3, back, -1), (3, back, 3), (-3, back, 3)],
                    [(0, 1, 2, 3)], (wall,))
    gi_scenes._camera(scene, "Camera", (0.0, -4.0, 1.0), (0.0, 0.0, 1.0), lens=35.0)
    gi_scenes._finish(scene, {})
    return back


def test_gpu_rays_cross_stacked_cutouts_as_the_numpy_rays_do(voxgi):
    """The traversal tests a cut-out's Alpha after its walk and walks again past a hit that
    does not count: through five half-transparent cards the GPU stops on each card as often as
    numpy does, and reaches the wall behind all five (1 in 32 rays), closest and any hit; an
    opaque quad in the first card's plane stops every ray that meets it, though the walk past
    the card starts in that plane. Past
    CUTOUT_LAYERS cards that do not count, the next one counts, as Cycles' transparent bounces
    end (numpy has no such cap)."""
    from test_gpu_bvh import gpu_ready

    from voxgi.render.gpu_bvh import GPUBVH, trace_rays
    from voxgi.render.gpu_scene import GPUScene
    from voxgi.voxgi_addon.scene.raycast import closest_hits, occluded
    from voxgi.voxgi_addon.scene.textures import CUTOUT_LAYERS

    back = stacked_veils(5, 0.5, frame=True)
    gpu_ready()
    scene = GPUScene(GPUBVH()).update(snapshot_now())
    tris = scene.tris
    assert tris.textures.cutout.sum() == 12  # five cards, the first in two halves
    rng = np.random.default_rng(5)
    n = 8000
    o = np.column_stack([rng.uniform(-1.0, 1.0, n), np.full(n, -1.0), rng.uniform(0.3, 1.7, n)])
    target = np.column_stack([rng.uniform(-1.0, 1.0, n), np.full(n, back), rng.uniform(0.3, 1.7, n)])
    d = (target - o) / np.linalg.norm(target - o, axis=1, keepdims=True)
    o, d = o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64)
    t, tri, _, _ = trace_rays(scene.bvh, o, d, 1e-4, np.inf)
    rt, rtri, _, _ = closest_hits(tris, o, d, 1e-4)
    layer = np.round((o[:, 1] + rt * d[:, 1]) / 0.25).astype(int)  # 0-4 the cards, 5+ the wall
    framed = o[:, 0] + (0.0 - o[:, 1]) / d[:, 1] * d[:, 0] < -0.01  # meets the frame
    assert (layer[framed] == 0).all() and 0.3 < framed.mean() < 0.7
    shares = np.bincount(np.minimum(layer[~framed], 5), minlength=6) / (~framed).sum()
    np.testing.assert_allclose(shares, [1 / 2, 1 / 4, 1 / 8, 1 / 16, 1 / 32, 1 / 32], atol=0.02)
    same = np.abs(t - rt) < 1e-4 * rt
    assert same.mean() > 0.995 and same[framed].all(), (same.mean(), same[framed].mean())
    # shadow rays ending before the wall: blocked unless every card lets them through
    max_t = (back - 0.1 - o[:, 1]) / d[:, 1]
    blocked = trace_rays(scene.bvh, o, d, 0.0, max_t, any_hit=True)
    reference = occluded(tris, o, d, max_t)
    assert (blocked == reference).mean() > 0.995
    assert abs(reference[~framed].mean() - 31 / 32) < 0.012 and blocked[framed].all()

    # clear cards (Alpha 0), more of them than the cap: the GPU stops on the one past the cap
    back = stacked_veils(CUTOUT_LAYERS + 3, 0.0)
    scene = GPUScene(GPUBVH()).update(snapshot_now())
    o = np.column_stack([rng.uniform(-1.0, 1.0, 200), np.full(200, -1.0), rng.uniform(0.3, 1.7, 200)])
    d = np.tile([0.0, 1.0, 0.0], (200, 1))
    t, tri, _, _ = trace_rays(scene.bvh, o, d, 1e-4, np.inf)
    rt, _, _, _ = closest_hits(scene.tris, o, d, 1e-4)
    np.testing.assert_allclose(rt, back + 1.0, rtol=1e-5)  # numpy passes them all
    np.testing.assert_allclose(t, 1.0 + 0.25 * CUTOUT_LAYERS, rtol=1e-5)


def test_fence_cards_against_cycles(voxgi):
    """Default settings, GPU: the wall through the gaps, slatted shadows, against Cycles."""
    scene = build()
    passes, lines = preview(scene)
    reference = np.load(REFS / "fence_cards.npz")
    limits = json.loads((REFS / "limits.json").read_text())["fence_cards"]
    mask = reference["Alpha"].astype(np.float64) > 0.5
    errors = {name: relative_l1(passes[name], reference[name].astype(np.float64), mask)
              for name in PASSES}
    print("fence cards vs Cycles:", {k: round(v, 4) for k, v in errors.items()})
    for name in PASSES:
        assert errors[name] <= limits[name], (name, errors, lines)


def test_fast_quality_sees_through_the_voxels_coverage(voxgi):
    """Fast quality: the cards' voxels keep their coverage (a cut-out's voxels are kept in
    proportion to its Alpha), so the cones, the primary rays and the shadows see the wall."""
    scene = build()
    scene.voxgi.quality = "FAST"
    bpy.ops.voxgi.voxelize()
    passes, lines = preview(scene)
    reference = np.load(REFS / "fence_cards.npz")
    limit = json.loads((REFS / "limits.json").read_text())["fence_cards_fast"]["Combined"]
    mask = reference["Alpha"].astype(np.float64) > 0.5
    error = relative_l1(passes["Combined"], reference["Combined"].astype(np.float64), mask)
    print(f"fence cards, Fast quality, Combined vs Cycles: {error:.4f}")
    assert error <= limit, (error, lines)


def test_numpy_and_gpu_agree_on_cutouts(voxgi):
    scene = build()
    gpu, _ = preview(scene, "AUTO", 80, 60)
    reference, _ = preview(scene, "NUMPY", 80, 60)
    for name in PASSES:
        error = relative_l1(gpu[name], reference[name])
        assert error < 0.02, (name, error)


def _transparent_mix_fence(fac_of_alpha=None):
    """The fence cards with the older cut-out setup: a Mix Shader (Transparent BSDF, the
    Principled BSDF) whose Fac is the image's alpha, or ``fac_of_alpha(tree, alpha socket)``'s
    output socket built of it. Returns the scene."""
    scene = build()
    tree = bpy.data.materials["Fence"].node_tree
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    image = next(n for n in tree.nodes if n.type == "TEX_IMAGE")
    tree.links.remove(bsdf.inputs["Alpha"].links[0])
    transparent = tree.nodes.new("ShaderNodeBsdfTransparent")
    mix = tree.nodes.new("ShaderNodeMixShader")
    alpha = image.outputs["Alpha"]
    tree.links.new(alpha if fac_of_alpha is None else fac_of_alpha(tree, alpha), mix.inputs["Fac"])
    tree.links.new(transparent.outputs["BSDF"], mix.inputs[1])
    tree.links.new(bsdf.outputs["BSDF"], mix.inputs[2])
    tree.links.new(mix.outputs["Shader"], tree.get_output_node("ALL").inputs["Surface"])
    return scene


def _matches_the_alpha_reference(scene):
    """The preview within 0.05 of the reference made with the Principled Alpha."""
    passes, lines = preview(scene)
    reference = np.load(REFS / "fence_cards.npz")
    mask = reference["Alpha"].astype(np.float64) > 0.5
    for name in ("Combined", "Diffuse Color"):
        error = relative_l1(passes[name], reference[name].astype(np.float64), mask)
        assert error <= 0.05, (name, error, lines)


def test_a_transparent_mix_shader_cuts_out_as_the_alpha_does(voxgi):
    """The older cut-out setup — Mix Shader (Transparent BSDF, Principled BSDF) whose Fac is
    the image's alpha — is Cycles' same surface: the snapshot reads the Fac as the Alpha, and
    the preview matches the reference made with the Principled Alpha."""
    scene = _transparent_mix_fence()
    fence = fence_material(snapshot_now())
    assert fence.alpha_texture >= 0 and fence.alpha_texture == fence.base_color_texture
    _matches_the_alpha_reference(scene)


def test_a_transparent_mix_whose_fac_comes_from_nodes_is_baked(voxgi):
    """The older cut-out setup with its Fac built of nodes (the image's alpha through a Math
    node's Greater Than, as tutorials threshold it): Cycles bakes the Fac over the UV map and
    it cuts out as the Alpha does. (It took the Fac's plain value: the fence was solid.)"""
    def threshold(tree, alpha):
        node = tree.nodes.new("ShaderNodeMath")
        node.operation = "GREATER_THAN"
        node.inputs[1].default_value = 0.5
        tree.links.new(alpha, node.inputs[0])
        return node.outputs[0]

    scene = _transparent_mix_fence(threshold)
    snapshot = snapshot_now()
    assert fence_material(snapshot).alpha_texture >= 0
    assert not [w for w in snapshot.warnings if "transparency" in w], snapshot.warnings
    _matches_the_alpha_reference(scene)

"""The viewport's sums on the GPU (render/gpu_accumulation.py) against the numpy reference
(voxgi_addon/preview/progressive.Accumulation): the same images after the same samples, for
every pass, on the film and off it, with the pixel filter's tails, a backdrop where no sample
landed, and tiles that reach past the image; and the GPU tracer's sums (GPUSums) giving the
same samples as the passes made from them on the CPU (preview.passes.finish_passes)."""
from __future__ import annotations

import numpy as np
import pytest
from test_viewport import gpu_ready

W, H = 37, 23  # not a multiple of the tiles: border tiles reach past the image


def random_passes(rng, w, h, with_holdout=True):
    from voxgi.voxgi_addon.preview.passes import PASS_NAMES

    passes = {name: rng.uniform(0.0, 2.0, (h, w, 3)).astype(np.float32) for name in PASS_NAMES}
    for colour in ("Diffuse Color", "Glossy Color"):  # colours of 0 (the background)
        passes[colour][rng.random((h, w)) < 0.2] = 0.0
    passes["Alpha"] = rng.uniform(0.0, 1.0, (h, w)).astype(np.float32)
    if with_holdout:
        passes["_holdout"] = rng.uniform(0.0, 0.3, (h, w)).astype(np.float32)
    return passes


def tiles():
    from voxgi.voxgi_addon.preview.progressive import tile_grid

    return [tile_grid(W, H, 16, 10, shift) for shift in ((0, 0), (5, 3), (11, 7))]


@pytest.mark.parametrize("pass_name,film,transparent", [
    ("Combined", True, False), ("Combined", True, True), ("Combined", False, False),
    ("Diffuse Indirect", False, False), ("Glossy Direct", False, False),
    ("Diffuse Color", False, False), ("Ambient Occlusion", False, False)])
def test_gpu_sums_equal_the_numpy_accumulation(voxgi, pass_name, film, transparent):
    from voxgi.render.gpu_accumulation import GPUAccumulation, read_rgba
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.progressive import (
        Accumulation,
        sample_tail_weights,
        scale_nearest,
    )

    gpu_ready()
    rng = np.random.default_rng(7)
    ours = GPUAccumulation(pass_name, W, H, film, transparent)
    reference = Accumulation(pass_name, W, H, film, transparent)
    backdrop = rng.uniform(0.0, 1.0, (5, 8, 4)).astype(np.float32)
    backdrop_texture = float_texture(np.flipud(backdrop).copy(), (8, 5))
    image = ours.estimate(backdrop=backdrop_texture)
    assert np.allclose(read_rgba(image), scale_nearest(backdrop, W, H))  # nothing landed yet
    for sample, grid in enumerate(tiles()):
        tails = sample_tail_weights(1.5, 4, sample)
        for rect in grid:
            passes = random_passes(rng, rect[2], rect[3], with_holdout=sample != 1)
            world = rng.uniform(0.0, 1.0, (rect[3], rect[2], 3)).astype(np.float32)
            weight = float(sample + 1)
            ours.add(rect, passes, gather_weight=weight, tails=tails, world=world)
            reference.add(rect, passes, gather_weight=weight, tails=tails, world=world)
            ours.estimate_into(image, rect)
        if sample == 0:  # part of the image: the estimate where tiles landed
            ours_image = read_rgba(ours.estimate(backdrop=backdrop_texture))
            expected = reference.estimate_rgba(backdrop)
            assert np.allclose(ours_image, expected, rtol=1e-4, atol=1e-5)
    # the image refreshed tile by tile (each tile's pixels and the one around its tails
    # reach) is the whole estimate, and the finished image
    assert np.allclose(read_rgba(image), reference.estimate_rgba(backdrop), rtol=1e-4, atol=1e-5)
    finished = read_rgba(ours.estimate())
    expected = reference.film_rgba(reference.finished(1.5), filter_width=1.5)
    assert np.allclose(finished, expected, rtol=1e-4, atol=1e-5)
    assert np.allclose(read_rgba(image), finished, rtol=1e-4, atol=1e-5)
    reference.tails = None  # the tails count: without them the samples' own means differ
    assert not np.allclose(finished, reference.film_rgba(reference.mean()), atol=1e-3)


def test_the_tracers_sums_give_the_passes_samples(voxgi):
    """A GPUSums (the tracer's sums, on the GPU) and the passes finish_passes makes of the same
    sums on the CPU add the same sample, for every pass."""
    from voxgi.render.gpu_accumulation import SUM_NAMES, GPUAccumulation, GPUSums, read_rgba
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.passes import PASS_NAMES, finish_passes

    gpu_ready()
    rng = np.random.default_rng(3)
    w, h = 19, 13
    texels = {name: rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32) for name in SUM_NAMES}
    for name in ("sum_b", "sum_c"):  # colours of 0 (the background)
        texels[name][rng.random((h, w)) < 0.25, :3] = 0.0
    textures = {name: float_texture(np.flipud(t).copy(), (w, h)) for name, t in texels.items()}
    flat = {name: t.reshape(-1, 4).astype(np.float64) for name, t in texels.items()}
    sums = {"emission": flat["sum_a"][:, :3], "coverage": flat["sum_a"][:, 3],
            "diffuse_color": flat["sum_b"][:, :3], "ao": flat["sum_b"][:, 3],
            "glossy_color": flat["sum_c"][:, :3], "holdout": flat["sum_c"][:, 3],
            "diffuse_indirect": flat["sum_d"][:, :3], "glossy_indirect": flat["sum_e"][:, :3],
            "glossy_direct": flat["sum_f"][:, :3], "diffuse_direct": flat["sum_g"][:, :3]}
    passes = finish_passes(sums, 1, w, h, filter_width=0.0)
    for pass_name in PASS_NAMES:
        film = pass_name == "Combined"
        on_gpu = GPUAccumulation(pass_name, w, h, film)
        on_cpu = GPUAccumulation(pass_name, w, h, film)
        on_gpu.add((0, 0, w, h), GPUSums(textures, w, h), gather_weight=2.0)
        on_cpu.add((0, 0, w, h), passes, gather_weight=2.0)
        assert np.allclose(read_rgba(on_gpu.estimate()), read_rgba(on_cpu.estimate()),
                           rtol=1e-5, atol=1e-6), pass_name


def test_bad_samples_are_refused_with_a_clear_error(voxgi):
    from voxgi.render.gpu_accumulation import GPUAccumulation

    gpu_ready()
    rng = np.random.default_rng(1)
    with pytest.raises(ValueError, match="unknown pass"):
        GPUAccumulation("Beauty", W, H)
    acc = GPUAccumulation("Combined", W, H, film=True)
    with pytest.raises(ValueError, match="sample for a"):
        acc.add((0, 0, 16, 10), random_passes(rng, 8, 8))
    passes = random_passes(rng, 16, 10)
    del passes["Alpha"]
    with pytest.raises(ValueError, match="Alpha"):
        acc.add((0, 0, 16, 10), passes)


@pytest.mark.parametrize("quality", ["FAST", "ACCURATE"])
def test_the_viewports_gpu_composition_equals_the_cpu_passes(voxgi, quality):
    """A viewport slice's sums composed on the GPU (``render_passes_stages(on_gpu=True)``: Fast's
    cones' terms through gpu_compose, Accurate's gathers) add the same sample as the passes the
    one-shot path composes (Fast: on the CPU, ``compose_passes``) from the same camera."""
    from test_viewport import HEIGHT, WIDTH, cornell, live_view

    from voxgi.render.gpu_accumulation import GPUAccumulation, GPUSums, read_rgba
    from voxgi.render.gpu_preview import finish
    from voxgi.render.gpu_volume import GPUVolume
    from voxgi.render.progressive import base_options, tracer
    from voxgi.voxgi_addon.preview.passes import PASS_NAMES
    from voxgi.voxgi_addon.scene.view_camera import camera_from_view

    scene = cornell()
    scene.voxgi.quality = quality
    _, live, view, window = live_view(scene)
    camera = camera_from_view(np.array(view), np.array(window), WIDTH, HEIGHT)
    options = base_options(scene.voxgi, WIDTH, HEIGHT)
    volume = GPUVolume()
    on_gpu = finish(tracer(live, volume, scene.voxgi, staged=True)(camera, WIDTH, HEIGHT,
                                                                    options))
    on_cpu = tracer(live, volume, scene.voxgi)(camera, WIDTH, HEIGHT, options)
    assert isinstance(on_gpu, GPUSums) and isinstance(on_cpu, dict)
    for pass_name in PASS_NAMES:
        film = pass_name == "Combined"
        images = []
        for sample in (on_gpu, on_cpu):
            acc = GPUAccumulation(pass_name, WIDTH, HEIGHT, film)
            acc.add((0, 0, WIDTH, HEIGHT), sample)
            images.append(read_rgba(acc.estimate()))
        error = np.abs(images[0] - images[1]).sum() / max(np.abs(images[1]).sum(), 1e-9)
        assert error < 2e-3, (pass_name, error)
        assert images[1][..., :3].max() > 0.0 or pass_name.startswith("Glossy"), pass_name


def random_surface(rng, w, h):
    """A tile's G-buffer as numpy arrays (``Accumulation.add``'s surface) and as the textures
    ``GPUAccumulation.add`` reads (position, normal, view, base; rows bottom to top): two
    planes of two materials, a textured share whose Base Color takes a few values (steps
    between some neighbours, none between others), and pixels that see nothing."""
    from voxgi.render.gpu_volume import float_texture

    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    second = (x + 0.5 * y) > 0.6 * w  # a crease: the second plane
    position = np.stack([x, y, np.where(second, 0.4 * x, 0.0)], -1)
    normal = np.where(second[..., None], np.array([-0.371, 0.0, 0.928]), np.array([0.0, 0.0, 1.0]))
    hit = rng.random((h, w)) > 0.1
    material = np.where(second, 3, 1) + (rng.random((h, w)) < 0.05)
    base = np.zeros((h, w, 4))
    textured = rng.random((h, w)) < 0.8
    base[..., :3] = rng.integers(0, 3, (h, w, 1)) * np.array([0.3, 0.2, 0.1]) + 0.05
    base[..., 3] = textured
    base[~textured] = 0.0
    surface = {"hit": hit, "material": material, "position": position, "normal": normal,
               "base": base}

    def texture(rgb, w4):
        return float_texture(np.flipud(np.dstack([rgb, w4])).astype(np.float32).copy(), (w, h))

    textures = (texture(position, hit.astype(np.float64)), texture(normal, np.zeros((h, w))),
                texture(np.zeros((h, w, 3)), material.astype(np.float64)),
                texture(base[..., :3], base[..., 3]))
    return surface, textures


def test_across_a_textures_steps_the_gpu_takes_the_filters_mean_as_numpy(voxgi):
    """With the tile's G-buffer the samples go into their neighbours across a step of one
    surface's texture by the filter's mean weights (``texture_steps``): the GPU's sums equal
    the numpy reference's, and differ from the sums by the offsets' weights alone."""
    from voxgi.render.gpu_accumulation import GPUAccumulation, read_rgba
    from voxgi.voxgi_addon.preview.passes import neighbour_weights
    from voxgi.voxgi_addon.preview.progressive import Accumulation, sample_tail_weights

    gpu_ready()
    rng = np.random.default_rng(11)
    ours = GPUAccumulation("Combined", W, H, True, False)
    reference = Accumulation("Combined", W, H, True, False)
    offsets_only = Accumulation("Combined", W, H, True, False)
    mean = neighbour_weights(1.5)
    for sample, grid in enumerate(tiles()):
        tails = sample_tail_weights(1.5, 4, sample)
        for rect in grid:
            passes = random_passes(rng, rect[2], rect[3])
            world = rng.uniform(0.0, 1.0, (rect[3], rect[2], 3)).astype(np.float32)
            surface, textures = random_surface(rng, rect[2], rect[3])
            ours.add(rect, passes, tails=tails, world=world, mean_tails=mean, surface=textures)
            reference.add(rect, passes, tails=tails, world=world, mean_tails=mean,
                          surface=surface)
            offsets_only.add(rect, passes, tails=tails, world=world)
    finished = read_rgba(ours.estimate())
    expected = reference.film_rgba(reference.finished(1.5), filter_width=1.5)
    assert np.allclose(finished, expected, rtol=1e-4, atol=1e-5)
    apart = offsets_only.film_rgba(offsets_only.finished(1.5), filter_width=1.5)
    assert np.abs(finished - apart).max() > 1e-3

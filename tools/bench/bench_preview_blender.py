"""One row of the ``preview`` benchmark (docs/gi_pipeline.md "Where a preview's time goes"),
run in a fresh process per scene and size
with the bpy venv: ``.venv/bin/python tools/bench/bench_preview_blender.py SCENE WIDTH HEIGHT
[--quick]``. Prints one ``RESULT {json}`` line that ``bench_preview.py`` turns into tables.

In this one process, in this order:

1. **The first preview in the process** (``render_scene_passes``, as F12), profiled as in 3,
   with every shader creation timed (``gpu.shader.create_from_info``; llvmpipe compiles the
   rest of a kernel at its first dispatch, which the per-stage profile shows). The section
   runs this process with an empty on-disk shader cache of its own (``MESA_SHADER_CACHE_DIR``),
   as on a new machine; with ``--first-only`` a later process times its first preview alone
   on the cache this one filled (every session after the first).
2. **The warm preview**: the median of ``repeats`` more, each after the radiance cache is
   dropped (as after any edit); its Combined error against Cycles at its default light paths.
3. **The machine's floor**, with trivial kernels on the scene's uploaded BVH: the texel-fetch
   rate of a kernel that only sums scattered ``texelFetch`` es (``_fetch_rate``), and the ray
   rate of closest-hit and any-hit rays traced by ``bvh_probe`` (nothing shaded) from points
   on the scene's triangles (``_ray_rates``). Then **one profiled preview**: every GPU
   dispatch of the tracer timed to its completion (a read-back of its output forces it; this
   run is slower than the warm one by those waits) and its work counted — rays (BVH
   traversals: a bounce or camera ray and each shadow ray) or texel fetches per kernel, from
   the kernel's dispatch size and push constants (``_traversals``, ``FETCHES``). Each stage's
   floor is its work at the rates of the trivial kernels.
4. **Cycles 16 and 64 spp + OpenImageDenoise** at its default light paths, and the reference
   (the stored 2048-spp one of tests/data/bounce_refs at 160 × 120 where there is one, else
   Cycles at ``REFERENCE_SPP`` (512 spp up to 160 × 120, 256 above) rendered once and kept in
   ``out/bench_refs``), and a second reference at its samples with another seed
   (``second_reference``): how far the two lie apart (their own noise, the floor under every
   error of the row), and each image's error against the two references' mean.
"""
from __future__ import annotations

import argparse
import collections
import json
import pathlib
import statistics
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(ROOT / "tools"), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon, median_seconds  # noqa: E402

STORED_REFS = ROOT / "tests" / "data" / "bounce_refs"
KEPT_REFS = ROOT / "out" / "bench_refs"
REFERENCE_SPP = {False: (512, 256), True: (64, 64)}  # by --quick: (up to 160 × 120, larger)
# Cycles' seeds: 1 the 16- and 64-spp renders (bench_bounces_blender), 0 the stored 2048-spp
# references (tools/make_bounce_references.py), these the kept references' and the second ones'
REFERENCE_SEED, SECOND_SEED = 3, 2
MAX_BOUNCES, DIFFUSE_BOUNCES, GLOSSY_BOUNCES = 12, 4, 4  # Cycles' default Light Paths
CITY_SIDE = 17  # 17 × 17 instanced domes: about 0.53 M triangles


def build(name: str, scene) -> None:
    """The benchmark's scenes, built as the tests build them."""
    import bounce_scenes
    import light_scenes
    import scale_scene

    if name in bounce_scenes.SCENES:
        bounce_scenes.build(name, scene)
    elif name in light_scenes.SCENES:
        light_scenes.build(name, scene)
    elif name == "city":
        scale_scene.city_block(scene, CITY_SIDE)
    elif name == "diorama":  # what an artist brings: a glTF download's meshes, each its own
        import diorama_scene

        diorama_scene.diorama(scene)
    else:
        raise SystemExit(f"unknown scene {name!r}")


# ------------------------------------------------------------------ the floor: trivial kernels

FETCH_KERNEL = """
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  ivec2 tsize = textureSize(source, 0);
  uint h = uint(px.y * size.x + px.x) * 2654435761u;
  vec4 sum = vec4(0.0);
  for (int i = 0; i < int(work.x); i++) {
    h = h * 1664525u + 1013904223u;
    sum += texelFetch(source, ivec2(int(h >> 8) % tsize.x, int(h >> 20) % tsize.y), 0);
  }
  imageStore(out_image, px, sum);
}
"""


def _fetch_rate(repeats: int) -> float:
    """Texel fetches per second of a kernel doing nothing else (scattered reads of a 256²
    RGBA32F texture that stays in the caches: the fastest fetches, a lower bound)."""
    import gpu

    from voxgi.render.gpu_shaders import LOCAL_SIZE
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture

    info = gpu.types.GPUShaderCreateInfo()
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE, 1)
    info.sampler(0, "FLOAT_2D", "source")
    info.push_constant("VEC4", "work")
    info.image(0, "RGBA32F", "FLOAT_2D", "out_image", qualifiers={"WRITE"})
    info.compute_source(FETCH_KERNEL)
    shader = gpu.shader.create_from_info(info)
    rng = np.random.default_rng(0)
    source = float_texture(rng.random((256, 256, 4), np.float32), (256, 256))
    width, height, per = 256, 256, 256
    out = gpu.types.GPUTexture((width, height), format="RGBA32F")

    def once():
        shader.bind()
        shader.uniform_sampler("source", source)
        shader.uniform_float("work", (float(per), 0.0, 0.0, 0.0))
        shader.image("out_image", out)
        gpu.compute.dispatch(shader, width // LOCAL_SIZE, height // LOCAL_SIZE, 1)
        read_texture(out)

    once()  # compiled and bound
    return width * height * per / median_seconds(once, repeats)


def _ray_rates(bvh, tris, repeats: int) -> tuple[float, float]:
    """(closest-hit, any-hit) rays per second of ``bvh_probe`` (a ray and nothing else) over
    the scene's BVH: rays from points on its triangles (as bounce and shadow rays start) in
    uniform directions, as long as the scene; uploaded once, timed from the dispatch to its
    output read back (1 MB, a few ms)."""
    from voxgi.render.gpu_bvh import dispatch_bvh
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.scene.snapshot import RAY_DIFFUSE

    rng = np.random.default_rng(1)
    positions = np.asarray(tris.positions, np.float64)
    side = 512
    count = side * side
    pick = rng.integers(0, len(positions), count)
    bary = rng.dirichlet((1.0, 1.0, 1.0), count)
    origins = np.einsum("nk,nkd->nd", bary, positions[pick])
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    extent = float(np.ptp(positions.reshape(-1, 3), axis=0).max())
    ray_o = np.concatenate([origins, np.full((count, 1), 1e-4)], axis=1)
    ray_d = np.concatenate([directions, np.full((count, 1), extent)], axis=1)
    inputs = {**bvh.inputs,
              "ray_origin": float_texture(ray_o.reshape(side, side, 4).astype(np.float32),
                                          (side, side)),
              "ray_direction": float_texture(ray_d.reshape(side, side, 4).astype(np.float32),
                                             (side, side))}
    rates = []
    for mode in (0.0, 1.0):  # closest hit, any hit
        def once():
            read_texture(dispatch_bvh("bvh_probe", inputs, side, side, {"mode": (mode, RAY_DIFFUSE, 0, 0)}))

        once()  # compiled
        rates.append(count / median_seconds(once, repeats))
    return rates[0], rates[1]


# ------------------------------------------------------------------ the profiled preview

# Kernel → the stage of the preview it belongs to (the tracer's timings name the same stages).
STAGES = {"bvh_gather": "diffuse+AO gather", "bvh_glossy": "glossy gather",
          "bvh_glossy world": "world glossy gather", "bvh_cache_paths": "radiance cache",
          "relax": "radiance cache", "denoise": "denoise + upsample",
          "upsample": "denoise + upsample", "bvh_direct": "direct light",
          "glossy_direct": "direct light", "bvh_emitter_glossy": "direct light",
          "aa_surface": "compose", "aa_light": "compose", "aa_mask": "compose",
          "aa_list": "compose", "aa_list_raw": "compose", "aa_resolve": "compose",
          "aa_index": "compose", "aa_place": "compose", "aa_tails": "compose",
          "gbuffer": "G-buffers",
          "upsample_field": "direct light", "upsample_field_list": "direct light"}
# Texel fetches per invocation of the kernels that trace no ray, read off their shaders: the
# à-trous filter's 25 taps × (value, variance, position, normal) plus its 3 × 3 variance
# prefilter, the upsample's 16 cells × 3, the composition's G-buffer, terms and sums; the
# emitters' field's 9 taps × 4 and its point (and list entry); the sub-pixel passes' list
# upsample also reads the three gathered terms at each tap (9 × 3 more) and the centre's; the
# sub-pixel samples' resolve its entry (4), each of the 3 × 3 centres' G-buffer and light
# (3 + 5) and the 2 × 2's seven sums (an upper bound).
FETCHES = {"denoise": 25 * 4 + 9, "upsample": 16 * 3, "aa_surface": 16, "aa_light": 5,
           "aa_mask": 2, "aa_list": 4, "aa_list_raw": 4,
           "relax": 16 * 8,
           "upsample_field": 9 * 4 + 2, "upsample_field_list": 9 * 7 + 6}


def _traversals(kernel, width, height, constants, lights) -> tuple[float, float]:
    """(rays, fetches) of one dispatch: rays are BVH traversals (each bounce or camera ray and
    each shadow ray: ``gpu_gather.rays_per_dispatch``'s count per bounce ray, ``lights`` the
    shadow traversals of a bounce hit)."""
    from voxgi.render.gpu_bvh import strata_side

    invocations = float(width * height)
    sampling = (constants or {}).get("sampling", (0.0, 1.0, 0.0, 1.0))
    per_hit = 1.0 + max(lights, 1) * strata_side(1) ** 2
    if kernel in ("bvh_gather", "bvh_glossy"):
        chunk = (constants or {}).get("chunk", (0.0, sampling[1], 0.0, 1.0))
        rays = min(float(chunk[1]), float(sampling[1]) - float(chunk[0]))
        return invocations * max(rays, 1.0) * per_hit, 0.0
    if kernel == "bvh_cache_paths":
        return invocations * per_hit, 0.0
    if kernel in ("bvh_direct", "bvh_emitter_glossy") and int(sampling[2] + 0.5) == 2:
        return 0.0, 0.0  # the emitters' sums alone (their field, the centres'): no ray
    if kernel == "bvh_direct":
        # an m × m block of strata: a shadow ray each — an upper bound from 3 × 3 on, where a
        # lamp whose 4 corner strata agree traces those 4 alone (direct_light._visible_share)
        block = float(sampling[1])
        return invocations * block * block, 0.0
    if kernel == "bvh_emitter_glossy":
        return invocations * float(sampling[1]), 0.0
    if kernel == "aa_resolve":  # a pixel's 3 × 3 centres once (9 textures), then per pass its
        # offsets, its sample's G-buffer and the 2 × 2 centres' seven sums
        passes = float((constants or {}).get("resolve", (1.0,))[0])
        return 0.0, invocations * (1 + 9 * 9 + passes * (1 + 3 + 4 * 7))
    return 0.0, invocations * FETCHES.get(kernel, 4)


def _on_gpu(lines) -> None:
    """Stop the row if the preview fell back to the numpy tracer (its report says why): the
    bench times the GPU tracer, and a fallback would time something else silently."""
    fallback = [text for _, text in lines if "numpy tracer used" in text]
    if fallback:
        raise SystemExit(fallback[0])


class Profile:
    """Every dispatch of the tracer timed to completion and its work counted, by stage."""

    def __init__(self):
        self.seconds = collections.defaultdict(float)
        self.rays = collections.defaultdict(float)
        self.fetches = collections.defaultdict(float)
        self.dispatches = collections.Counter()

    def add(self, kernel, seconds, rays=0.0, fetches=0.0):
        stage = STAGES.get(kernel, "other")
        self.seconds[stage] += seconds
        self.rays[stage] += rays
        self.fetches[stage] += fetches
        self.dispatches[stage] += 1


def _finish(texture) -> None:
    """Wait for ``texture``'s dispatch: read one of its texels' rows (a tiny read-back)."""
    from voxgi.render.gpu_tracer import read_texture

    read_texture(texture)


def profiled(fn, profile: Profile):
    """Run ``fn`` with the tracer's dispatch functions wrapped to time and count each one."""
    from voxgi.render import gpu_bvh, gpu_compose, gpu_gather, gpu_preview, gpu_scene, gpu_tails

    # shadow traversals a bounce hit makes (strata aside): the one lamp it picks, the world's two
    # techniques, the emitters' one (gpu_gather.rays_per_dispatch)
    every = gpu_scene.current_scene().lights if gpu_scene.current_scene() else ()
    lamps = sum(light.type not in ("WORLD", "EMITTERS") for light in every)
    lights = min(lamps, 1) + sum(2 if light.type == "WORLD" else 1 for light in every
                                 if light.type in ("WORLD", "EMITTERS"))
    saved = []

    def patch(module, name, wrapper):
        saved.append((module, name, getattr(module, name)))
        setattr(module, name, wrapper(getattr(module, name)))

    def bvh_wrapper(original):
        def dispatch_bvh(kernel, inputs, width, height, constants=None, images=None):
            t0 = time.perf_counter()
            out = original(kernel, inputs, width, height, constants, images)
            _finish(out[0] if isinstance(out, tuple) else out)
            grid = (constants or {}).get("grid", (0, 0, 0, 0.0))
            # grid.w's flag 1 is the world mode (gpu_gather.gather_steps; 2 the lattice, 4 the sun apart)
            world = kernel == "bvh_glossy" and int(grid[3] + 0.5) & 1
            name = "bvh_glossy world" if world else kernel
            rays, fetches = _traversals(kernel, width, height, constants, lights)
            profile.add(name, time.perf_counter() - t0, rays, fetches)
            return out
        return dispatch_bvh

    def compose_wrapper(original):
        def run(kernel, samplers, inputs, outputs, width, height, constants=None, over=None):
            t0 = time.perf_counter()
            out = original(kernel, samplers, inputs, outputs, width, height, constants, over)
            _finish(next(iter(out.values())))
            profile.add(kernel, time.perf_counter() - t0,
                        *_traversals(kernel, *(over or (width, height)), constants, lights))
            return out
        return run

    def timed(kernel, finish_index=0):
        def wrapper(original):
            def call(*args, **kwargs):
                t0 = time.perf_counter()
                out = original(*args, **kwargs)
                first = out[finish_index] if isinstance(out, tuple) else out
                if hasattr(first, "read"):
                    _finish(first)
                elif hasattr(first, "position"):
                    _finish(first.position)
                count = 0.0
                if kernel in ("denoise", "upsample"):
                    cells = args[0].width * args[0].height
                    passes = 1 if kernel == "upsample" else \
                        kwargs.get("iterations", args[6] if len(args) > 6 else 4)
                    count = cells * FETCHES[kernel] * passes
                elif kernel in ("upsample_field", "upsample_field_list"):
                    count = first.width * first.height * FETCHES[kernel]
                profile.add(kernel, time.perf_counter() - t0, 0.0, float(count))
                return out
            return call
        return wrapper

    def tails_wrapper(kernel):  # gpu_tails.GPUTails' methods: (invocations, fetches each)
        def wrapper(original):
            def call(self, *args):
                t0 = time.perf_counter()
                out = original(self, *args)
                _finish(self.sums["a"])
                if kernel == "aa_tails":  # 7 sums, 9 index fetches, every neighbour listed
                    w, h = self.reached_size
                    count = w * h * (7 + 9 + 9 * len(args[1]) * 8)
                elif kernel == "aa_place":
                    count = args[3][0] * args[3][1] * 8
                else:
                    count = args[1][0] * args[1][1]
                profile.add(kernel, time.perf_counter() - t0, 0.0, float(count))
                return out
            return call
        return wrapper

    patch(gpu_bvh, "dispatch_bvh", bvh_wrapper)
    patch(gpu_gather, "dispatch_bvh", bvh_wrapper)
    for name, kernel in (("__init__", "aa_index"), ("place", "aa_place"), ("add", "aa_tails")):
        patch(gpu_tails.GPUTails, name, tails_wrapper(kernel))
    patch(gpu_compose, "run", compose_wrapper)
    patch(gpu_preview, "_run", compose_wrapper)
    patch(gpu_gather, "relax_gpu", timed("relax"))
    for module in _importers("denoise"):
        patch(module, "denoise", timed("denoise"))
    for module in _importers("upsample"):
        patch(module, "upsample", timed("upsample"))
    for name in ("upsample_field", "upsample_field_list"):
        for module in _importers(name):
            patch(module, name, timed(name))
    for module in _importers("rasterize"):
        patch(module, "rasterize", timed("gbuffer"))
    try:
        return fn()
    finally:
        for module, name, original in reversed(saved):
            setattr(module, name, original)


def _importers(name):
    """The tracer's modules that hold a function ``name`` imported by name."""
    from voxgi.render import gbuffer, gpu_gather, gpu_preview

    owner = {"denoise": gpu_gather, "upsample": gpu_gather, "rasterize": gbuffer,
             "upsample_field": gpu_gather, "upsample_field_list": gpu_gather}[name]
    function = getattr(owner, name)
    return [m for m in (gpu_gather, gpu_preview, gbuffer) if getattr(m, name, None) is function]


# ------------------------------------------------------------------ Cycles

def cycles_render(scene, width, height, samples, denoise, seed=1):
    """(passes, seconds) of Cycles at its default light paths (as bench_bounces_blender)."""
    from bench_bounces_blender import cycles_default_paths

    return cycles_default_paths(scene, width, height, samples, denoise, seed)


def reference(name, scene, width, height, quick):
    """(Combined, mask, where it came from): Cycles at its default light paths."""
    stored = STORED_REFS / f"{name}.npz"
    if not quick and (width, height) == (160, 120) and stored.exists():
        with np.load(stored) as data:
            return data["Combined"].astype(np.float64), data["Alpha"] > 0.5, \
                "stored 2048 spp"
    spp = REFERENCE_SPP[quick][width * height > 160 * 120]
    # a seed of its own: Cycles 16 and 64 spp render with seed 1, and a reference with that
    # seed shares their first samples (its noise then leans towards theirs)
    kept = KEPT_REFS / f"{name}_{width}x{height}_{spp}_seed{REFERENCE_SEED}.npz"
    if not kept.exists():
        passes, _ = cycles_render(scene, width, height, spp, False, seed=REFERENCE_SEED)
        kept.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(kept, Combined=passes["Combined"], Alpha=passes["Alpha"])
    with np.load(kept) as data:
        return data["Combined"].astype(np.float64), data["Alpha"] > 0.5, f"Cycles {spp} spp"


def second_reference(name, scene, width, height, quick) -> np.ndarray:
    """Combined of a second reference: Cycles at the reference's samples with another seed,
    rendered once and kept in ``out/bench_refs``. How far the two lie apart is the references'
    own noise, the floor under every error of the row (docs/gi_pipeline.md "How much of the
    error is the reference's own noise")."""
    spp = 2048 if not quick and (width, height) == (160, 120) and \
        (STORED_REFS / f"{name}.npz").exists() else REFERENCE_SPP[quick][width * height > 160 * 120]
    kept = KEPT_REFS / f"{name}_{width}x{height}_{spp}_seed{SECOND_SEED}.npz"
    if not kept.exists():
        passes, _ = cycles_render(scene, width, height, spp, False, seed=SECOND_SEED)
        kept.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(kept, Combined=passes["Combined"])
    with np.load(kept) as data:
        return data["Combined"].astype(np.float64)


def relative_l1(ours, ref, mask) -> float:
    a, b = np.asarray(ours, np.float64)[mask], ref[mask]
    return float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-12))


# ------------------------------------------------------------------ the row

def _timings(lines) -> dict[str, float]:
    """The preview's own stage timings (its last report line: "name 12.3 ms, …"), seconds."""
    timings = {}
    for part in lines[-1][1].split(", "):
        stage, _, number = part.removesuffix(" ms").rpartition(" ")
        timings[stage] = float(number) / 1000.0
    return timings


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("width", type=int)
    ap.add_argument("height", type=int)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--first-only", action="store_true",
                    help="time the first preview only and print FIRST {json} (bench_preview.py "
                         "runs it in a later session, Mesa's shader cache filled by the row's)")
    args = ap.parse_args(argv)
    import bpy  # noqa: F401 - gpu comes with it
    import gpu

    compiles = []
    create = gpu.shader.create_from_info

    def counted_create(info):
        t0 = time.perf_counter()
        shader = create(info)
        compiles.append(time.perf_counter() - t0)
        return shader

    gpu.shader.create_from_info = counted_create
    load_addon()
    from voxgi.render import gpu_context, gpu_gather
    from voxgi.render.gpu_scene import current_scene
    from voxgi.render.pipeline import render_scene_passes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build(args.scene, scene)
    scene.voxgi.bounce_source = "CYCLES"
    width, height = args.width, args.height
    repeats = 1 if args.quick else 2

    def preview():
        return render_scene_passes(bpy.context, scene, None, width, height)

    ready, why = gpu_context.ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    first_profile = Profile()  # the first preview: compiles and first uses, by stage
    t0 = time.perf_counter()
    passes, lines = profiled(preview, first_profile)
    first = time.perf_counter() - t0
    _on_gpu(lines)
    first_compiles = (len(compiles), sum(compiles))
    if args.first_only:
        print("FIRST " + json.dumps({"first": first, "compiles": first_compiles[0],
                                     "compile_seconds": first_compiles[1]}), flush=True)
        return 0
    first_timings = _timings(lines)
    warm_times = []
    for _ in range(repeats):
        gpu_gather.drop_shared_cache()  # as after an edit: the cache is built again
        t0 = time.perf_counter()
        passes, lines = preview()
        warm_times.append(time.perf_counter() - t0)
    warm = statistics.median(warm_times)
    timings = _timings(lines)
    # the floor's rates on this scene's BVH, after the previews (the BVH is uploaded)
    gpu_scene = current_scene()
    fetch_rate = _fetch_rate(3)
    closest_rate, any_rate = _ray_rates(gpu_scene.bvh, gpu_scene.tris, 3)
    profile = Profile()
    gpu_gather.drop_shared_cache()
    t0 = time.perf_counter()
    _on_gpu(profiled(preview, profile)[1])
    profiled_total = time.perf_counter() - t0
    ref, mask, ref_source = reference(args.scene, scene, width, height, args.quick)
    error = relative_l1(passes["Combined"], ref, mask)
    second = second_reference(args.scene, scene, width, height, args.quick)
    both = 0.5 * (ref + second)  # the two references' mean: half their noise's variance
    cycles, against_both = {}, {"voxgi": relative_l1(passes["Combined"], both, mask)}
    for samples in (16, 64):
        cycles_passes, seconds = cycles_render(scene, width, height, samples, True)
        cycles[samples] = (seconds, relative_l1(cycles_passes["Combined"], ref, mask))
        against_both[f"cycles{samples}"] = relative_l1(cycles_passes["Combined"], both, mask)
    ray_rate = 0.5 * (closest_rate + any_rate)
    stages = {}
    for stage in profile.seconds:
        floor = profile.rays[stage] / ray_rate + profile.fetches[stage] / fetch_rate
        stages[stage] = {"seconds": profile.seconds[stage], "rays": profile.rays[stage],
                         "fetches": profile.fetches[stage], "floor": floor,
                         "dispatches": profile.dispatches[stage],
                         "first": first_profile.seconds.get(stage, 0.0)}
    triangles = int(len(gpu_scene.tris.positions))
    result = {"scene": args.scene, "width": width, "height": height, "triangles": triangles,
              "first": first, "warm": warm, "error": error, "reference": ref_source,
              "reference_noise": relative_l1(second, ref, mask), "against_both": against_both,
              "compiles": first_compiles[0], "compile_seconds": first_compiles[1],
              "cycles16": cycles[16], "cycles64": cycles[64], "stages": stages,
              "profiled_total": profiled_total, "fetch_rate": fetch_rate,
              "closest_rate": closest_rate, "any_rate": any_rate, "timings": timings,
              "first_timings": first_timings}
    print("RESULT " + json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

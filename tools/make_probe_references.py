"""Cycles references of light-probe irradiance in the light scenes (issue 17: "a probe bake of
the HDRI scene is within 15 % of Cycles' irradiance"; tests/blender/test_probe_hdri.py).

Usage: ``.venv/bin/python tools/make_probe_references.py [--scene hdri_courtyard] [--probes 16]
[--samples 256] [--out tests/data/probe_refs]``

The scene (``light_scenes``) is baked with the default settings (Bake Probes as a user runs
it); ``--probes`` of its enabled probes, drawn with a fixed seed, each get two
equirectangular Cycles renders (``WIDTH`` × ``HEIGHT``, ``--samples`` each, seeds 0 and 1) from
the probe's position with no bounce at all (max bounces 0: a surface seen shows its emission
and the direct light it reflects, diffuse and glossy — one bounce as the probe holds it) and
the Environment pass (the world seen straight, which a transparent film leaves out of
Combined). The incoming radiance of each pixel, its direction (the panorama's row and column)
and solid angle (its latitude band's share) give the irradiance for each of ``NORMALS``:
E(n) = Σ L max(n·ω, 0) Ω; and the same radiance projected on SH L2 gives what a perfect L2
probe would hold (``sh.irradiance`` of it), the representation's own error. Lamps are hidden
from the panoramas' camera rays: a probe holds the light lamps shed on surfaces, not the lamps
seen straight (docs/probes.md "Bake").

``<out>/<scene>.npz``: positions (P, 3), normals (5, 3), irradiance (P, 5, 3) (the two
renders' mean), irradiance_l2 (P, 5, 3), noise (P, 5) (half the two renders' relative
difference, the mean's standard error within a factor of about 1.5). ``<out>/summary.json``:
per scene, samples, size, seconds.
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_gi_references import REPO_ROOT, load_addon  # noqa: E402

WIDTH, HEIGHT = 256, 128
NORMALS = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                    [0.0, -1.0, 0.0]])
PROBE_SEED = 17


def panorama_directions(width: int = WIDTH, height: int = HEIGHT) -> tuple[np.ndarray, np.ndarray]:
    """((H·W, 3) unit directions of the pixel centres, (H·W,) solid angles) of an
    equirectangular Cycles camera with rotation (90°, 0, −90°), row 0 on top: elevation
    π/2 − (i + ½)π/H, azimuth π − (j + ½)2π/W (checked against the Position pass in
    ``render_probe``)."""
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    el = math.pi / 2 - (rows + 0.5) * math.pi / height
    phi = math.pi - (cols + 0.5) * 2 * math.pi / width
    dirs = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1)
    edges = math.pi / 2 - np.arange(height + 1) * math.pi / height
    solid = np.repeat((np.sin(edges[:-1]) - np.sin(edges[1:])) * (2 * math.pi / width), width)
    return dirs.reshape(-1, 3), solid


def panorama_camera(scene):
    import bpy

    data = bpy.data.cameras.new("Probe Panorama")
    data.type = "PANO"
    data.panorama_type = "EQUIRECTANGULAR"
    data.clip_start = 1e-4  # probes can sit a centimetre or two above the ground
    camera = bpy.data.objects.new("Probe Panorama", data)
    camera.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return camera


def render_probe(scene, camera, position, samples, seed):
    """(H·W, 3) radiance arriving at ``position`` from each panorama pixel."""
    from cycles_passes import render_cycles_passes

    camera.location = tuple(float(c) for c in position)
    passes = render_cycles_passes(scene, WIDTH, HEIGHT, samples, diffuse_bounces=0,
                                  glossy_bounces=0, seed=seed,
                                  extra_passes={"Environment": "use_pass_environment",
                                                "Position": "use_pass_position"})
    dirs, _ = panorama_directions()
    seen = passes["Alpha"].reshape(-1) > 0.999
    offset = passes["Position"].reshape(-1, 3)[seen] - np.asarray(position)
    length = np.linalg.norm(offset, axis=1)
    far = length > 0.05
    agreement = np.einsum("ij,ij->i", offset[far] / length[far, None], dirs[seen][far])
    if far.any() and np.median(agreement) < math.cos(math.radians(1.0)):
        raise RuntimeError(f"the panorama's directions are not {panorama_directions.__doc__}")
    radiance = passes["Combined"] + passes["Environment"]
    return radiance.reshape(-1, 3).astype(np.float64)


def irradiance(radiance, normals=NORMALS):
    """(len(normals), 3): exact E(n) of the panorama's pixels, and E(n) of their SH L2
    projection."""
    from voxgi.voxgi_addon.probes import sh

    dirs, solid = panorama_directions()
    weighted = radiance * solid[:, None]
    exact = np.maximum(normals @ dirs.T, 0.0) @ weighted
    coefficients = np.einsum("nk,nc->kc", sh.sh_basis(dirs), weighted)
    return exact, sh.irradiance(coefficients, normals)


def chosen_probes(grid, count):
    """Indices of ``count`` enabled probes drawn with ``PROBE_SEED`` (ascending)."""
    enabled = np.flatnonzero(grid.enabled)
    rng = np.random.default_rng(PROBE_SEED)
    return np.sort(rng.choice(enabled, size=min(count, len(enabled)), replace=False))


def main(argv=None):
    load_addon()
    import bpy
    import light_scenes

    from voxgi.blender.probe_store import load_grids

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="hdri_courtyard", choices=list(light_scenes.SCENES))
    parser.add_argument("--probes", type=int, default=16)
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--out", type=pathlib.Path, default=REPO_ROOT / "tests" / "data" / "probe_refs")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    light_scenes.build(args.scene, scene)
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    grid = load_grids(scene)[0]
    indices = chosen_probes(grid, args.probes)
    positions = np.asarray(grid.positions, np.float64)[indices]
    camera = panorama_camera(scene)
    for obj in scene.objects:
        if obj.type == "LIGHT":
            obj.visible_camera = False
    exact, l2, noise = [], [], []
    start = time.perf_counter()
    for index, p in zip(indices, positions):
        pair = [irradiance(render_probe(scene, camera, p, args.samples, seed)) for seed in (0, 1)]
        e = 0.5 * (pair[0][0] + pair[1][0])
        exact.append(e)
        l2.append(0.5 * (pair[0][1] + pair[1][1]))
        spread = np.abs(pair[0][0] - pair[1][0]).sum(axis=1) / np.maximum(2 * e.sum(axis=1), 1e-12)
        noise.append(spread)
        print(f"probe {index} at {np.round(p, 3)}: E {np.round(e.mean(axis=1), 3)} "
              f"(noise {np.round(spread, 4)})", flush=True)
    seconds = time.perf_counter() - start
    path = args.out / f"{args.scene}.npz"
    np.savez_compressed(path, positions=positions.astype(np.float32), normals=NORMALS,
                        indices=indices, irradiance=np.array(exact, np.float32),
                        irradiance_l2=np.array(l2, np.float32), noise=np.array(noise, np.float32))
    summary_path = args.out / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    summary[args.scene] = {"probes": len(indices), "samples_per_render": args.samples,
                           "renders_per_probe": 2, "size": [WIDTH, HEIGHT],
                           "seconds": round(seconds, 1)}
    summary_path.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
    print(f"{path} ({path.stat().st_size / 1024:.1f} KB) in {seconds:.0f} s")


if __name__ == "__main__":
    main()

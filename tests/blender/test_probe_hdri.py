"""Issue 17: "a probe bake of the HDRI scene is within 15 % of Cycles' irradiance" (docs/probes.md
"Lights at the probe").

The HDRI courtyard (tests/blender/light_scenes.py: lit only by an equirect world with a 1.5°
sun disc about 50 000 times the sky, turned by a Mapping node) is baked as a user bakes it
(Bake Probes, default settings); each probe of tests/data/probe_refs (drawn at random by
tools/make_probe_references.py, which rendered Cycles panoramas at them) is compared, for the
up normal and the four horizontal axes, with Cycles' irradiance there: E(n) = ∫ L max(n·ω, 0)
dω of the light arriving at the probe, straight from the world and off the lit surfaces.

A probe holds SH L2, which cannot hold a sun: for a normal facing away from it, L2's ringing
is several times the sky light Cycles finds there (the references carry Cycles' own light
projected on L2, to tell that representation error from the bake's).
"""
import json
import pathlib
from dataclasses import dataclass

import bpy
import light_scenes
import numpy as np

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "probe_refs"
LIMIT = 0.15


def _relative(ours, cycles):
    """(P, 5) |ΔE| / E per probe and normal (RGB summed)."""
    return np.abs(ours - cycles).sum(axis=-1) / np.maximum(np.abs(cycles).sum(axis=-1), 1e-9)


@dataclass
class Comparison:
    """The default bake of a light scene against its Cycles references (tests/data/probe_refs).
    Only probes that Cycles finds any light at (not one outside a closed room) are kept; dark
    holds the bake's largest |E| at the others. error, floor, old : (P, 5) relative irradiance
    error per probe and normal of the bake, of Cycles' own light in SH L2, and of the uniform
    directions alone (the bake before next-event estimation at the probe); per_probe,
    old_per_probe : (P,) relative L1 over the normals."""

    index: np.ndarray
    positions: np.ndarray
    cycles: np.ndarray
    ours: np.ndarray
    error: np.ndarray
    floor: np.ndarray
    old: np.ndarray
    per_probe: np.ndarray
    old_per_probe: np.ndarray
    noise: float
    samples: int
    dark: float


def _compare(name) -> Comparison:
    from voxgi.blender.probe_store import load_grids
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.voxgi_addon.probes import sh
    from voxgi.voxgi_addon.probes.bake import hit_radiance
    from voxgi.voxgi_addon.probes.validity import trace_probe_rays
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    scene = bpy.context.scene
    light_scenes.build(name, scene)
    refs = np.load(REFS / f"{name}.npz")
    summary = json.loads((REFS / "summary.json").read_text())[name]
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    grid = load_grids(scene)[0]
    positions = np.asarray(grid.positions, np.float64)
    # the reference probes are the bake's own (placement and relocation do not depend on light)
    distance = np.linalg.norm(positions[None] - refs["positions"][:, None], axis=2)
    index = distance.argmin(axis=1)
    assert distance[np.arange(len(index)), index].max() < 1e-4
    assert grid.enabled[index].all()
    normals = refs["normals"]
    cycles = refs["irradiance"].astype(np.float64)
    ours = np.stack([sh.irradiance(np.asarray(grid.sh[i], np.float64), normals) for i in index])

    # the bake before next-event estimation at the probe: the same uniform rays see the map where
    # they miss and the emission they land on, nothing is drawn from the lights
    snapshot, _ = snapshot_or_error(bpy.context)
    tris = world_triangles(snapshot)
    dirs = sh.sample_directions(scene.voxgi.probe_directions, scene.voxgi.probe_seed)
    rays = trace_probe_rays(tris, positions[index], dirs)
    n = len(dirs)
    radiance = hit_radiance(snapshot, tris, np.repeat(positions[index], n, axis=0),
                            np.tile(dirs, (len(index), 1)), rays.t.ravel(), rays.triangle.ravel(),
                            rays.u.ravel(), rays.v.ravel(), 1, scene.voxgi.probe_seed)
    uniform = np.stack([sh.irradiance(c, normals)
                        for c in sh.project(radiance.reshape(len(index), n, 3), dirs)])

    lit = np.abs(cycles).sum(axis=(1, 2)) > 0
    dark = float(np.abs(ours[~lit]).max()) if (~lit).any() else 0.0
    index, cycles, ours, uniform = index[lit], cycles[lit], ours[lit], uniform[lit]

    def per_probe(e):
        return np.abs(e - cycles).sum(axis=(1, 2)) / np.abs(cycles).sum(axis=(1, 2))

    return Comparison(index, positions[index], cycles, ours, _relative(ours, cycles),
                      _relative(refs["irradiance_l2"].astype(np.float64)[lit], cycles),
                      _relative(uniform, cycles), per_probe(ours), per_probe(uniform),
                      float(refs["noise"][lit].max()), int(summary["samples_per_render"]), dark)


def _report(c: Comparison) -> None:
    for k, i in enumerate(c.index):
        print(f"probe {i} at {np.round(c.positions[k], 2)}: Cycles E {np.round(c.cycles[k].mean(1), 2)}, "
              f"probe {np.round(c.ours[k].mean(1), 2)}; error {np.round(c.error[k], 3)} "
              f"(uniform rays {np.round(c.old[k], 2)}, L2 of Cycles' own light {np.round(c.floor[k], 3)})")
    # the worst only over normals with some light (≥ 1/1000 of the probe's brightest normal's)
    energy = c.cycles.sum(axis=-1)
    seen = energy >= 1e-3 * energy.max(axis=1, keepdims=True)
    print(f"{len(c.index)} probes × 5 normals (Cycles: 2 × {c.samples} spp panoramas, noise ≤ "
          f"{c.noise:.4f}): error median {np.median(c.error):.3f}, 90th percentile "
          f"{np.percentile(c.error, 90):.3f}, worst {c.error[seen].max():.3f} ({seen.sum()} normals "
          f"with light). Uniform rays only: median {np.median(c.old):.3f}, worst "
          f"{c.old[seen].max():.2f}. SH L2 of Cycles' own light: median {np.median(c.floor):.3f}, "
          f"worst {c.floor[seen].max():.3f}; the bake where that is within 5 %: worst "
          f"{c.error[c.floor < 0.05].max():.3f} ({(c.floor < 0.05).sum()} of {c.floor.size})")
    print(f"per probe (relative L1 over its five normals, {len(c.index)} probes that Cycles finds "
          f"light at; the others' largest |E| {c.dark:.2g}): worst {c.per_probe.max():.3f}, median "
          f"{np.median(c.per_probe):.3f}; uniform rays only: worst {c.old_per_probe.max():.3f}, "
          f"median {np.median(c.old_per_probe):.3f}")


def test_probe_bake_of_the_hdri_courtyard_is_within_15_percent_of_cycles(voxgi):
    c = _compare("hdri_courtyard")
    _report(c)
    assert c.noise < 0.01  # the references are converged
    # every probe's irradiance within the limit, and the typical normal's
    assert c.per_probe.max() < LIMIT
    assert np.median(c.error) < LIMIT
    # where an L2 probe can hold Cycles' light (its own projection within 5 %), every normal of
    # every probe is within the limit; elsewhere (a normal facing away from the sun, which L2
    # rings into) the bake is no further off than Cycles' own L2 projection plus the limit
    assert c.error[c.floor < 0.05].max() < LIMIT
    assert (c.error < c.floor + LIMIT).all()
    # the old bake (the uniform directions alone) found the sun by luck
    assert c.old_per_probe.max() > 3 * LIMIT and np.median(c.old) > LIMIT


def test_probe_bake_of_the_emissive_room_is_within_15_percent_of_cycles(voxgi):
    """The room lit by an emissive ceiling panel, a glowing sphere (both sampled at the probe by
    power, MIS with the uniform directions) and a spot (whose light the probes hold as it
    bounces off the walls); black world. The typical probe is within the limit and closer than
    with the uniform directions alone. The bounce hits draw 2 × 2 shadow rays here
    (``bake.EMITTER_SAMPLES``): with one, a hit beside an emitter (the ceiling 5 cm above the
    panel, lit from a few centimetres) got an area sample's 1/r² now and then, and the worst
    probe read 0.24, 0.37 once the hits' glossy lobes reflect it too (docs/probes.md "Bake")."""
    c = _compare("emissive_room")
    _report(c)
    assert c.noise < 0.02
    assert c.dark < 1e-3  # a probe outside the room (under its floor) stays dark
    assert np.median(c.per_probe) < LIMIT
    assert c.per_probe.max() < 0.2  # 0.124 measured
    assert np.median(c.per_probe) < 0.75 * np.median(c.old_per_probe)
    assert np.median(c.error) < np.median(c.old)

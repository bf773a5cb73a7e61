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

import bpy
import light_scenes
import numpy as np
import pytest

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "probe_refs"
LIMIT = 0.15


def _relative(ours, cycles):
    """(P, 5) |ΔE| / E per probe and normal (RGB summed)."""
    return np.abs(ours - cycles).sum(axis=-1) / np.maximum(np.abs(cycles).sum(axis=-1), 1e-9)


@pytest.fixture
def courtyard(voxgi):
    scene = bpy.context.scene
    light_scenes.build("hdri_courtyard", scene)
    return scene


def test_probe_bake_of_the_hdri_courtyard_is_within_15_percent_of_cycles(courtyard):
    from voxgi.blender.probe_store import load_grids
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.voxgi_addon.probes import sh
    from voxgi.voxgi_addon.probes.bake import hit_radiance
    from voxgi.voxgi_addon.probes.validity import trace_probe_rays
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    refs = np.load(REFS / "hdri_courtyard.npz")
    summary = json.loads((REFS / "summary.json").read_text())["hdri_courtyard"]
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    grid = load_grids(courtyard)[0]
    positions = np.asarray(grid.positions, np.float64)
    # the reference probes are the bake's own (placement and relocation do not depend on light)
    distance = np.linalg.norm(positions[None] - refs["positions"][:, None], axis=2)
    index = distance.argmin(axis=1)
    assert distance[np.arange(len(index)), index].max() < 1e-4
    assert grid.enabled[index].all()
    normals = refs["normals"]
    cycles = refs["irradiance"].astype(np.float64)
    ours = np.stack([sh.irradiance(np.asarray(grid.sh[i], np.float64), normals) for i in index])
    error = _relative(ours, cycles)
    floor = _relative(refs["irradiance_l2"].astype(np.float64), cycles)

    # the bake before next-event estimation at the probe: the same uniform rays see the map where
    # they miss (hit_radiance with the world seen), nothing drawn from the map
    snapshot, _ = snapshot_or_error(bpy.context)
    tris = world_triangles(snapshot)
    dirs = sh.sample_directions(courtyard.voxgi.probe_directions, courtyard.voxgi.probe_seed)
    rays = trace_probe_rays(tris, positions[index], dirs)
    n = len(dirs)
    radiance = hit_radiance(snapshot, tris, np.repeat(positions[index], n, axis=0),
                            np.tile(dirs, (len(index), 1)), rays.t.ravel(), rays.triangle.ravel(),
                            rays.u.ravel(), rays.v.ravel(), 1, courtyard.voxgi.probe_seed)
    uniform = sh.project(radiance.reshape(len(index), n, 3), dirs)
    old = _relative(np.stack([sh.irradiance(c, normals) for c in uniform]), cycles)

    for k, i in enumerate(index):
        print(f"probe {i} at {np.round(positions[i], 2)}: Cycles E {np.round(cycles[k].mean(1), 2)}, "
              f"probe {np.round(ours[k].mean(1), 2)}; error {np.round(error[k], 3)} "
              f"(uniform rays {np.round(old[k], 2)}, L2 of Cycles' own light {np.round(floor[k], 3)})")
    print(f"{len(index)} probes × {len(normals)} normals (Cycles: 2 × {summary['samples_per_render']} "
          f"spp panoramas, noise ≤ {refs['noise'].max():.4f}): error median {np.median(error):.3f}, "
          f"90th percentile {np.percentile(error, 90):.3f}, worst {error.max():.3f}. Uniform rays only: median "
          f"{np.median(old):.3f}, worst {old.max():.2f}. SH L2 of Cycles' own light: median "
          f"{np.median(floor):.3f}, worst {floor.max():.3f}; the bake where that is within 5 %: worst "
          f"{error[floor < 0.05].max():.3f} ({(floor < 0.05).sum()} of {floor.size})")
    assert refs["noise"].max() < 0.01  # the references are converged
    per_probe = np.abs(ours - cycles).sum(axis=(1, 2)) / np.abs(cycles).sum(axis=(1, 2))
    old_per_probe = np.abs(np.stack([sh.irradiance(c, normals) for c in uniform]) - cycles).sum(
        axis=(1, 2)) / np.abs(cycles).sum(axis=(1, 2))
    print(f"per probe (relative L1 over its five normals): worst {per_probe.max():.3f}, median "
          f"{np.median(per_probe):.3f}; uniform rays only: worst {old_per_probe.max():.3f}, median "
          f"{np.median(old_per_probe):.3f}")
    # every probe's irradiance within the limit, and the typical normal's
    assert per_probe.max() < LIMIT
    assert np.median(error) < LIMIT
    # where an L2 probe can hold Cycles' light (its own projection within 5 %), every normal of
    # every probe is within the limit; elsewhere (a normal facing away from the sun, which L2
    # rings into) the bake is no further off than Cycles' own L2 projection plus the limit
    assert error[floor < 0.05].max() < LIMIT
    assert (error < floor + LIMIT).all()
    # the old bake (the uniform directions alone) found the sun by luck
    assert old_per_probe.max() > 3 * LIMIT and np.median(old) > LIMIT

"""Baked probes through Blender's glTF exporter and importer (docs/gltf_probes.md "Blender").

The test Cornell box and the thin-wall rooms are baked, exported with ``export_scene.gltf``
(GLB, and the box also as .gltf + .bin and as embedded .gltf), checked by the Khronos
glTF-Validator (zero errors; the npm package pinned in web/package.json, installed here with
``npm ci`` when missing) and imported into a fresh file: every ProbeGrid array comes back equal,
with its dtype, and the name. Damaged extension data is reported by the importer as an error
naming the volume and the field, the meshes still import and the probe store is left as it was.
The add-on is also found by the exporter when installed from the built zip.
"""
from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import shutil
import subprocess
import sys
import textwrap

import bpy
import gltf_probe_scenes
import numpy as np
import pytest

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
WEB = REPO_ROOT / "web"
VALIDATE = REPO_ROOT / "tools" / "gltf_validate" / "validate.mjs"
EXT = "VOXGI_irradiance_volumes"


@pytest.fixture(scope="session")
def gltf_validator():
    """``validate(path) -> report`` through tools/gltf_validate/validate.mjs; the validator comes
    from web/package.json (pinned) and is installed with ``npm ci --prefix web`` when missing."""
    node, npm = shutil.which("node"), shutil.which("npm")
    assert node and npm, "node and npm are needed for the glTF-Validator"
    package = json.loads((WEB / "package.json").read_text())
    version = package["devDependencies"]["gltf-validator"]
    installed = WEB / "node_modules" / "gltf-validator" / "package.json"
    if not installed.exists() or json.loads(installed.read_text())["version"] != version:
        proc = subprocess.run([npm, "ci", "--prefix", str(WEB), "--no-audit", "--no-fund"],
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, f"npm ci failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    assert json.loads(installed.read_text())["version"] == version

    def validate(path):
        proc = subprocess.run([node, str(VALIDATE), str(path)], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        report = json.loads(proc.stdout)
        assert report["validatorVersion"] == version
        return report

    return validate


def errors_of(report) -> list:
    return [m for m in report["issues"]["messages"] if m["severity"] == 0]


def store(voxgi):
    from voxgi.blender import probe_store

    return probe_store


def assert_grids_equal(got, expected):
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        for f in dataclasses.fields(b):
            x, y = getattr(a, f.name), getattr(b, f.name)
            if isinstance(y, np.ndarray):
                assert isinstance(x, np.ndarray) and x.dtype == y.dtype, (f.name, getattr(x, "dtype", x), y.dtype)
                assert x.shape == y.shape and np.array_equal(x, y), f.name
            else:
                assert type(x) is type(y) and x == y, (f.name, x, y)


def import_fresh(path, **options):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with gltf_probe_scenes.addon_enabled():
        return bpy.ops.import_scene.gltf(filepath=str(path), **options)


@pytest.mark.parametrize("name, export_format", [
    ("box", "GLB"), ("box", "GLTF_SEPARATE"), ("box", "GLTF_EMBEDDED"), ("thin_wall", "GLB")])
def test_baked_probes_survive_a_gltf_round_trip_bit_for_bit(voxgi, gltf_validator, tmp_path, name,
                                                            export_format):
    probe_store = store(voxgi)
    scene = gltf_probe_scenes.build_scene(name)
    grids = gltf_probe_scenes.bake(scene, name)
    assert len(grids) == 1 and len(grids[0].volume_cells) > 0 and grids[0].flags.any()
    path = tmp_path / (f"{name}.glb" if export_format == "GLB" else f"{name}.gltf")
    gltf_prefs = bpy.context.preferences.addons["io_scene_gltf2"].preferences
    gltf_prefs.allow_embedded_format = export_format == "GLTF_EMBEDDED"  # off by default
    try:
        gltf_probe_scenes.export_gltf(path, export_format)
    finally:
        gltf_prefs.allow_embedded_format = False
    if export_format == "GLTF_SEPARATE":
        assert (tmp_path / f"{name}.bin").exists()

    report = gltf_validator(path)
    assert errors_of(report) == [], report["issues"]
    assert EXT in report["info"]["extensionsUsed"]
    assert EXT not in report["info"].get("extensionsRequired", [])

    assert import_fresh(path) == {"FINISHED"}
    scene = bpy.context.scene
    assert_grids_equal(probe_store.load_grids(scene), grids)
    # the Empty made of the volume's node is marked; a second export keeps one node per volume
    marked = [o for o in scene.objects if "voxgi_irradiance_volume" in o.keys()]
    assert len(marked) == 1 and marked[0].type == "EMPTY"
    again = tmp_path / f"again_{name}.glb"
    gltf_probe_scenes.export_gltf(again)
    from voxgi.voxgi_addon.files import gltf_probes as fmt

    document = fmt.read_gltf(again).document
    assert len([n for n in document["nodes"] if n["name"].startswith("VoxGI Volume")]) == 1
    assert_grids_equal([d.grid for d in fmt.read_volumes(again)], grids)


def test_the_helper_writes_files_and_a_probe_preview(voxgi, tmp_path):
    files = gltf_probe_scenes.export_probe_scenes(tmp_path, names=("box",))
    box = files["box"]
    assert box["gltf"].name == "box.glb" and box["gltf"].stat().st_size > 1000
    preview = np.load(box["preview_npz"])
    assert preview["irradiance"].shape == (72, 96, 3) and preview["irradiance"].dtype == np.float32
    np.testing.assert_array_equal(preview["irradiance"], preview["diffuse_indirect"] * np.float32(np.pi))
    assert preview["irradiance"].max() > 0
    camera = json.loads(box["camera"].read_text())
    assert camera["type"] == "perspective" and (camera["width"], camera["height"]) == (96, 72)
    # Blender's camera at (0, -3.4, 1) is at (0, 1, 3.4) in glTF's +Y-up frame
    np.testing.assert_allclose(camera["matrix_world"][12:15], [0.0, 1.0, 3.4], atol=1e-6)


def test_no_bake_or_option_off_writes_no_extension(voxgi, tmp_path):
    from voxgi.voxgi_addon.files import gltf_probes as fmt

    scene = gltf_probe_scenes.build_scene("box")
    gltf_probe_scenes.export_gltf(tmp_path / "unbaked.glb")
    assert EXT not in json.dumps(fmt.read_gltf(tmp_path / "unbaked.glb").document)
    gltf_probe_scenes.bake(scene, "box")
    assert scene.voxgi_gltf.export_probes  # on by default
    scene.voxgi_gltf.export_probes = False
    gltf_probe_scenes.export_gltf(tmp_path / "off.glb")
    assert EXT not in json.dumps(fmt.read_gltf(tmp_path / "off.glb").document)
    scene.voxgi_gltf.export_probes = True
    gltf_probe_scenes.export_gltf(tmp_path / "on.glb")
    assert len(fmt.read_volumes(tmp_path / "on.glb")) == 1


def test_the_export_dialog_has_the_option(voxgi):
    import io_scene_gltf2

    from voxgi.blender import gltf_probes

    assert io_scene_gltf2.exporter_extension_layout_draw.get(gltf_probes.DRAW_KEY) is gltf_probes.draw_export
    assert voxgi.glTF2ExportUserExtension is gltf_probes.GltfExportProbes
    assert voxgi.glTF2ImportUserExtension is gltf_probes.GltfImportProbes
    assert voxgi.draw_import is gltf_probes.draw_import


def _damaged(path, out, change):
    """Write ``out``: the GLB at ``path`` with ``change(document, binary)`` applied."""
    from voxgi.voxgi_addon.files import gltf_probes as fmt

    gltf = fmt.read_gltf(path)
    document, binary = gltf.document, bytearray(gltf.buffer(0))
    change(document, binary)
    pathlib.Path(out).write_bytes(fmt.glb_bytes(document, binary))
    return out


def _volume(document):
    return document["extensions"][EXT]["volumes"][0]


def _probe_out_of_range(document, binary):
    view = document["bufferViews"][_volume(document)["volumeProbes"]]
    binary[view["byteOffset"]:view["byteOffset"] + 4] = (10**6).to_bytes(4, "little")


def _truncated_view(document, binary):
    view = document["bufferViews"][_volume(document)["volumeMasks"]]
    view["byteLength"] = len(binary) + 64 - view["byteOffset"]


@pytest.mark.parametrize("change, field", [
    (_probe_out_of_range, "volumeProbes"),
    (_truncated_view, "volumeMasks"),
    (lambda d, b: _volume(d).update(dims=[4, 0, 4]), "dims"),
    (lambda d, b: _volume(d).pop("sh"), "sh"),
    (lambda d, b: _volume(d).update(probeCount=_volume(d)["probeCount"] + 1), "positions"),
])
def test_damaged_probes_are_reported_and_the_rest_imports(voxgi, tmp_path, change, field):
    probe_store = store(voxgi)
    scene = gltf_probe_scenes.build_scene("box")
    grids = gltf_probe_scenes.bake(scene, "box")
    good = tmp_path / "box.glb"
    gltf_probe_scenes.export_gltf(good)
    bad = _damaged(good, tmp_path / "bad.glb", change)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    kept = dataclasses.replace(grids[0], name="kept before the import")
    probe_store.save_grids(scene, [kept])
    text_before = bpy.data.texts[probe_store.text_name(scene.name_full)].as_string()
    with gltf_probe_scenes.addon_enabled():
        with pytest.raises(RuntimeError) as raised:
            bpy.ops.import_scene.gltf(filepath=str(bad))
    message = str(raised.value)
    print("importer reported:", message)
    assert "VoxGI" in message and "volume 0 'Scene'" in message and f"{field}:" in message
    assert "Test Box" in bpy.data.objects and "Tall Block" in bpy.data.objects  # the scene imported
    assert bpy.data.texts[probe_store.text_name(scene.name_full)].as_string() == text_before
    assert [g.name for g in probe_store.load_grids(scene)] == ["kept before the import"]


def test_a_moved_volume_node_moves_the_grid_and_a_rotated_one_is_refused(voxgi):
    from voxgi.blender.gltf_probes import grid_to_blender
    from voxgi.voxgi_addon.files import gltf_probes as fmt
    from voxgi.voxgi_addon.probes.grid import ProbeGrid

    grid = ProbeGrid(origin=[0, 0, 0], volume_size=[1, 1, 1], dims=[1, 1, 1],
                     positions=np.zeros((8, 3), np.float32), sh=np.zeros((8, 9, 3), np.float32),
                     volume_cells=np.zeros(1, np.uint32), volume_probes=np.arange(8, dtype=np.uint32)[None],
                     volume_masks=np.zeros((1, 8), np.uint64), name="g")
    document = fmt.new_document()
    fmt.add_volumes(document, bytearray(), [grid])
    document["nodes"][0]["translation"] = [1.0, 2.0, 3.0]  # glTF: x 1, up 2, towards the viewer 3
    document["nodes"][0]["scale"] = [2.0, 2.0, 2.0]
    moved = grid_to_blender(fmt.DecodedVolume(dataclasses.replace(grid), 0, 0), document)
    np.testing.assert_allclose(moved.origin, [1.0, -3.0, 2.0])
    np.testing.assert_allclose(moved.volume_size, [2.0, 2.0, 2.0])
    document["nodes"][0]["rotation"] = [0.0, 0.0, 0.0, 1.0]
    with pytest.raises(fmt.GltfProbesError, match="volume 0 'g': node: .*axis-aligned"):
        grid_to_blender(fmt.DecodedVolume(dataclasses.replace(grid), 0, 0), document)


INSTALLED_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import bpy

    zip_path, out = sys.argv[1:3]
    assert bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True) == {"FINISHED"}
    bpy.ops.wm.read_homefile(use_empty=True)
    mesh = bpy.data.meshes.new("Floor")
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("Floor", mesh)
    bpy.context.scene.collection.objects.link(obj)
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.location = (0, 0, 1)
    bpy.context.scene.collection.objects.link(light)
    settings = bpy.context.scene.voxgi
    settings.probe_resolution, settings.probe_directions = 2, 16
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    assert bpy.ops.export_scene.gltf(filepath=out) == {"FINISHED"}
    bpy.ops.wm.read_homefile(use_empty=True)
    assert bpy.ops.import_scene.gltf(filepath=out) == {"FINISHED"}
    store = sys.modules["bl_ext.user_default.voxgi.blender.probe_store"]
    print("VOXGI_RESULT " + json.dumps({"grids": len(store.load_grids(bpy.context.scene))}))
    """
)


def test_the_installed_extension_exports_and_imports_its_probes(voxgi, tmp_path):
    import test_extension_install as install

    from voxgi.voxgi_addon.files import gltf_probes as fmt

    zip_path = install._build_zip(tmp_path / "dist")
    script = tmp_path / "installed_gltf.py"
    script.write_text(INSTALLED_SCRIPT)
    out = tmp_path / "installed.glb"
    env = install._subprocess_env(tmp_path)
    proc = subprocess.run([sys.executable, str(script), str(zip_path), str(out)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("VOXGI_RESULT ")]
    assert proc.returncode == 0 and len(lines) == 1, (
        f"exit {proc.returncode}\n--- stdout ---\n{proc.stdout[-4000:]}\n--- stderr ---\n{proc.stderr[-4000:]}")
    assert json.loads(lines[0].split(" ", 1)[1]) == {"grids": 1}
    volumes = fmt.read_volumes(out)
    assert len(volumes) == 1 and len(volumes[0].grid.positions) > 0
    assert os.path.getsize(out) > 0

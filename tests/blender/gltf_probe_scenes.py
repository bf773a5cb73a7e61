"""Baked probe scenes exported through Blender's glTF exporter with VOXGI_irradiance_volumes
(docs/gltf_probes.md), for the glTF tests here and the web viewer's tests.

``export_probe_scenes(directory)`` builds, bakes and exports two scenes:

* ``box`` — ``scenes.build_test_cornell_box`` (2 m Cornell box, open at −Y, 80 W point light,
  camera at (0, −3.4, 1) looking along +Y), probes k = 4, 64 directions;
* ``thin_wall`` — ``scenes.build_thin_wall_room`` (two rooms split by a 2 cm wall, lit on one
  side, orthographic camera straight above), probes k = 8, 64 directions, masks on.

Per scene it writes ``<name>.glb`` (default export settings plus cameras and lights, the
probes on), and — unless ``preview=False`` — VoxGI's own preview of the scene camera with
Diffuse Indirect from the probes (``voxgi.render_preview(indirect_source='PROBES')``):
``<name>_preview.exr`` (every pass) and ``<name>_preview.npz`` (float32 (H, W, 3) arrays
``diffuse_indirect``, ``diffuse_color``, ``diffuse_direct``, ``combined``, row 0 at the top,
plus ``irradiance`` = π · Diffuse Indirect, what the probes give at each pixel's surface), and
``<name>_camera.json`` (the camera in glTF's frame, +Y up: type, world matrix column-major,
yfov or ortho half extents, clip distances, image size).

``export_probe_scenes`` registers the add-on from this checkout (``ensure_addon``) unless one is
registered already (the Blender test session's ``voxgi`` fixture); ``python
tests/blender/gltf_probe_scenes.py OUTDIR`` runs it from the command line. The exporter
finds the hooks only on an add-on listed as enabled in the preferences; ``addon_enabled`` lists
the test-loaded ``voxgi`` package there while the export runs.
"""
from __future__ import annotations

import contextlib
import json
import math
import pathlib
import sys

import bpy
import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import scenes  # noqa: E402

PREVIEW_SIZE = {"box": (96, 72), "thin_wall": (128, 64)}
BAKES = {
    "box": dict(probe_resolution=4, probe_directions=64, probe_masks=True),
    "thin_wall": dict(probe_resolution=8, probe_directions=64, probe_masks=True),
}
NAMES = tuple(BAKES)
# glTF (x, y, z) = (x_b, z_b, −y_b)
BLENDER_TO_GLTF = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], np.float64)


def ensure_addon() -> None:
    """Register VoxGI from this checkout (as ``voxgi``) unless an add-on is registered already:
    the Blender test session's fixture does it; other callers need not."""
    if hasattr(bpy.types.Scene, "voxgi"):
        return
    import importlib
    import os
    import tempfile

    if "voxgi" not in sys.modules:
        link_dir = tempfile.mkdtemp(prefix="voxgi-pkg-")
        os.symlink(HERE.parents[1], os.path.join(link_dir, "voxgi"), target_is_directory=True)
        sys.path.insert(0, link_dir)
    importlib.import_module("voxgi").register()


def addon_package() -> str:
    """Name of the loaded VoxGI package (``voxgi`` in the tests, ``bl_ext.….voxgi`` installed)."""
    for name in ("voxgi", *sorted(n for n in sys.modules if n.endswith(".voxgi"))):
        module = sys.modules.get(name)
        if module is not None and hasattr(module, "glTF2ExportUserExtension"):
            return name
    raise RuntimeError("the VoxGI add-on is not loaded")


@contextlib.contextmanager
def addon_enabled(package: str | None = None):
    """List ``package`` in Preferences › Add-ons while the block runs (io_scene_gltf2 asks the
    preferences which add-ons' hooks to call); an entry that was there already is left."""
    package = package or addon_package()
    addons = bpy.context.preferences.addons
    added = None
    if package not in addons.keys():
        added = addons.new()
        added.module = package
    try:
        yield
    finally:
        if added is not None and package in bpy.context.preferences.addons.keys():
            bpy.context.preferences.addons.remove(bpy.context.preferences.addons[package])


def build_scene(name: str, scene=None):
    """Build scene ``name`` ('box' or 'thin_wall') into ``scene`` (the context scene)."""
    scene = scene or bpy.context.scene
    if name == "box":
        scenes.build_test_cornell_box(scene)
    elif name == "thin_wall":
        scenes.build_thin_wall_room(scene)
        scene.voxgi.span_mode = "MANUAL"
        scene.voxgi.base_span = 0.07
        scene.voxgi.grid_resolution = "64"
    else:
        raise ValueError(f"unknown probe scene {name!r} (one of {NAMES})")
    scene.voxgi.bounce_source = "MANUAL"  # one bounce, however the add-on was loaded
    scene.voxgi.bounces = 1
    return scene


def bake(scene, name: str):
    """Bake the probes of scene ``name`` with its small test settings; returns the grids."""
    for key, value in BAKES[name].items():
        setattr(scene.voxgi, key, value)
    assert bpy.ops.voxgi.bake_probes() == {"FINISHED"}
    from importlib import import_module

    return import_module(f"{addon_package()}.blender.probe_store").load_grids(scene)


def export_gltf(path, export_format: str = "GLB", **options) -> None:
    """``bpy.ops.export_scene.gltf`` of the context scene with VoxGI's hooks enabled; cameras
    and lights included (the web viewer draws the same view), everything else at its default."""
    settings = dict(filepath=str(path), export_format=export_format, export_cameras=True,
                    export_lights=True)
    settings.update(options)
    with addon_enabled():
        assert bpy.ops.export_scene.gltf(**settings) == {"FINISHED"}


def camera_description(scene) -> dict:
    """The scene camera in glTF's frame (+Y up), as a viewer sets it up."""
    camera = scene.camera
    m = BLENDER_TO_GLTF @ np.array(camera.matrix_world, np.float64)
    data = camera.data
    width, height = scene.render.resolution_x, scene.render.resolution_y
    out = {"name": camera.name, "matrix_world": m.T.ravel().tolist(), "width": width,
           "height": height, "znear": data.clip_start, "zfar": data.clip_end}
    if data.type == "ORTHO":
        half_x = data.ortho_scale / 2 if width >= height else data.ortho_scale / 2 * width / height
        out.update(type="orthographic", xmag=half_x, ymag=half_x * height / width)
    else:
        sensor = data.sensor_width if width >= height else data.sensor_width * height / width
        xfov = 2 * math.atan(sensor / (2 * data.lens))
        out.update(type="perspective", yfov=2 * math.atan(math.tan(xfov / 2) * height / width),
                   aspectRatio=width / height)
    return out


def write_probe_preview(scene, exr_path, npz_path, size) -> dict[str, np.ndarray]:
    """VoxGI's preview with Diffuse Indirect from the probes: the EXR and the NPZ described in
    the module docstring; returns the NPZ's arrays."""
    from importlib import import_module

    read_exr = import_module(f"{addon_package()}.voxgi_addon.files.exr").read_exr
    width, height = size
    assert bpy.ops.voxgi.render_preview(filepath=str(exr_path), resolution_x=width, resolution_y=height,
                                        indirect_source="PROBES") == {"FINISHED"}
    channels = read_exr(exr_path)

    def rgb(name):
        return np.stack([channels[f"{name}.{c}"] for c in "RGB"], axis=-1).astype(np.float32)

    arrays = {"diffuse_indirect": rgb("Diffuse Indirect"), "diffuse_color": rgb("Diffuse Color"),
              "diffuse_direct": rgb("Diffuse Direct"), "combined": rgb("Combined")}
    arrays["irradiance"] = (arrays["diffuse_indirect"] * np.float32(math.pi)).astype(np.float32)
    np.savez(npz_path, **arrays)
    return arrays


def export_probe_scenes(directory, names=NAMES, *, export_format: str = "GLB",
                        preview: bool = True) -> dict[str, dict[str, pathlib.Path]]:
    """Build, bake and export each scene of ``names`` into ``directory`` (made if missing), each
    from a fresh empty file; returns ``{name: {"gltf": …, "preview_exr": …, "preview_npz": …,
    "camera": …}}`` (the preview keys only with ``preview``). ``export_format`` is the
    exporter's ('GLB', 'GLTF_SEPARATE' or 'GLTF_EMBEDDED'). The last scene stays open."""
    directory = pathlib.Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    suffix = ".glb" if export_format == "GLB" else ".gltf"
    out = {}
    for name in names:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_addon()
        scene = build_scene(name)
        bake(scene, name)
        files = {"gltf": directory / f"{name}{suffix}"}
        export_gltf(files["gltf"], export_format)
        files["camera"] = directory / f"{name}_camera.json"
        files["camera"].write_text(json.dumps(camera_description(scene), indent=1))
        if preview:
            files["preview_exr"] = directory / f"{name}_preview.exr"
            files["preview_npz"] = directory / f"{name}_preview.npz"
            write_probe_preview(scene, files["preview_exr"], files["preview_npz"], PREVIEW_SIZE[name])
        out[name] = files
    return out


def main(argv=None) -> int:
    """``python tests/blender/gltf_probe_scenes.py OUTDIR [--no-preview] [--format …]``: both
    scenes into OUTDIR."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory")
    parser.add_argument("--no-preview", action="store_true")
    parser.add_argument("--format", default="GLB", choices=("GLB", "GLTF_SEPARATE", "GLTF_EMBEDDED"))
    args = parser.parse_args(argv)
    files = export_probe_scenes(args.directory, export_format=args.format, preview=not args.no_preview)
    for name, paths in files.items():
        print(name, {k: str(v) for k, v in paths.items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())

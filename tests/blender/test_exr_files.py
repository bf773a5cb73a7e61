"""Our EXR files open in Blender; Blender's multilayer EXR files open with ``voxgi_addon.exr``."""
from __future__ import annotations

import bpy
import numpy as np
import pytest


@pytest.fixture
def exr(voxgi):
    from voxgi.voxgi_addon.files import exr

    return exr


def _save_as_single_layer_exr(image, path, scene):
    """Blender decodes ``image`` and saves its default pass as a float, uncompressed EXR."""
    settings = scene.render.image_settings
    settings.media_type = "IMAGE"
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.exr_codec = "NONE"
    image.save_render(str(path), scene=scene)


def test_our_multilayer_file_loads_in_blender(exr, tmp_path):
    rng = np.random.default_rng(0)
    names = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Diffuse Color", "Glossy Indirect",
             "Ambient Occlusion")
    layers = {name: rng.random((6, 10, 3)).astype(np.float32) for name in names}
    path = tmp_path / "preview.exr"
    exr.write_exr(path, layers)

    image = bpy.data.images.load(str(path))
    tree = bpy.data.node_groups.new("Probe", "CompositorNodeTree")
    node = tree.nodes.new("CompositorNodeImage")
    node.image = image
    assert image.type == "MULTILAYER"
    assert set(names) <= {socket.name for socket in node.outputs}  # Blender sees every pass

    # Blender decodes the pixels: its re-save of the default pass has our size and values.
    _save_as_single_layer_exr(image, tmp_path / "resaved.exr", bpy.context.scene)
    resaved = exr.read_exr(tmp_path / "resaved.exr")
    assert resaved["R"].shape == (6, 10)
    for c, channel in enumerate("RGB"):
        np.testing.assert_array_equal(resaved[channel], layers["Combined"][:, :, c])


def _tiny_cycles_render(scene, path):
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, 0.0, 3.0)
    scene.camera = camera
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(light)
    light.location = (0.3, 0.2, 1.0)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = 11, 37  # 3 ZIP chunks, the last partial
    scene.render.resolution_percentage = 100
    scene.view_layers[0].use_pass_diffuse_direct = True
    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return settings


def test_blender_multilayer_files_read_with_every_codec(exr, tmp_path):
    scene = bpy.context.scene
    settings = _tiny_cycles_render(scene, tmp_path / "default.exr")
    # Blender 5.0's default: one part per pass, ZIP, 32-bit float.
    parts = exr.exr_parts(tmp_path / "default.exr")
    assert [p["name"] for p in parts] == ["ViewLayer.Combined", "ViewLayer.Diffuse Direct"]
    assert {p["compression"] for p in parts} == {3}
    reference = exr.read_exr(tmp_path / "default.exr")
    direct = reference["ViewLayer.Diffuse Direct.R"]
    assert direct.shape == (37, 11) and direct.max() > 0
    assert set(exr.read_exr_passes(tmp_path / "default.exr")) == {"Combined", "Diffuse Direct"}

    result = bpy.data.images["Render Result"]
    for codec, interleave, depth in [("NONE", False, "32"), ("RLE", False, "32"),
                                     ("ZIPS", True, "16"), ("ZIP", True, "32")]:
        settings.exr_codec, settings.use_exr_interleave, settings.color_depth = codec, interleave, depth
        path = tmp_path / f"{codec}.exr"
        result.save_render(str(path), scene=scene)
        assert len(exr.exr_parts(path)) == (1 if interleave else 2)  # interleave = single part
        got = exr.read_exr(path)
        assert set(got) == set(reference)
        for name, plane in reference.items():
            expected = plane.astype(np.float16).astype(np.float32) if depth == "16" else plane
            np.testing.assert_array_equal(got[name], expected, err_msg=f"{codec} {name}")

"""Materials between Blender and GFG files (main thread).

A material whose surface is a Principled BSDF becomes a PRINCIPLED GFG material (its input
values, and the image linked into Base Color as a texture path); a shader mix the preview
reads as one Principled BSDF (``snapshot.shader_mix``) becomes one of its mixed values; any
other becomes LAMBERT with the viewport colour. Import builds the same node setup back, so exporting an imported
material gives the same values. Texture paths are stored relative to the .gfg file's folder
with '/' separators (absolute when on another drive).
"""
from __future__ import annotations

import os

import bpy
import numpy as np

from ...voxgi_addon.files.gfg import Material
from ...voxgi_addon.files.gfg.spec import LambertSlot, MaterialLogic, PrincipledSlot
from ..snapshot import shader_mix
from ..snapshot.node_groups import surface_node

# Principled BSDF input per uniform slot (values of 1, 3 or 4 floats).
PRINCIPLED_INPUTS = (
    (PrincipledSlot.BASE_COLOR, "Base Color"),
    (PrincipledSlot.ROUGHNESS, "Roughness"),
    (PrincipledSlot.METALLIC, "Metallic"),
    (PrincipledSlot.SPECULAR, "Specular IOR Level"),
    (PrincipledSlot.EMISSION_COLOR, "Emission Color"),
    (PrincipledSlot.EMISSION_STRENGTH, "Emission Strength"),
    (PrincipledSlot.ALPHA, "Alpha"),
)


def _socket_value(socket) -> np.ndarray:
    value = socket.default_value
    return np.array(value[:] if hasattr(value, "__len__") else [value], np.float32)


def texture_path(image, directory: str) -> str | None:
    """The image file's path relative to ``directory`` ('/' separators), or None without a file."""
    if image.source != "FILE" or not image.filepath:
        return None
    path = os.path.normpath(bpy.path.abspath(image.filepath, library=image.library))
    try:
        path = os.path.relpath(path, directory)
    except ValueError:  # another drive (Windows)
        pass
    return path.replace(os.sep, "/")


def export_material(material, directory: str, warnings: list[str]) -> Material:
    """The GFG material of a ``bpy.types.Material``."""
    node_tree = material.node_tree
    mixed = None if node_tree is None else shader_mix.read(node_tree)
    if mixed is not None:  # a Mix Shader of BSDFs, a Glossy: one Principled of mixed values
        return _mixed(material, mixed, warnings)
    principled = None if node_tree is None else surface_node(node_tree, "BSDF_PRINCIPLED")
    if principled is None:
        return Material(material.name_full, MaterialLogic.LAMBERT,
                        {LambertSlot.COLOR: np.array(material.diffuse_color[:], np.float32)})
    result = Material(material.name_full, MaterialLogic.PRINCIPLED)
    for slot, name in PRINCIPLED_INPUTS:
        result.uniforms[slot] = _socket_value(principled.inputs[name])
    base = principled.inputs["Base Color"]
    if base.is_linked:
        node = base.links[0].from_node
        path = texture_path(node.image, directory) if node.type == "TEX_IMAGE" and node.image else None
        if path is not None:
            result.textures[PrincipledSlot.BASE_COLOR] = path
        else:
            warnings.append(f"Material '{material.name}': Base Color comes from a '{node.name}' node "
                            "without an image file; only its value is exported")
    return result


def _mixed(material, shader, warnings: list[str]) -> Material:
    """A shader mix (``snapshot.shader_mix``) as the PRINCIPLED material the preview reads:
    its mixed values (a Fac or input from nodes at its own value, said in ``warnings``)."""
    result = Material(material.name_full, MaterialLogic.PRINCIPLED)
    base = np.clip(shader_mix.value(shader, "base"), 0.0, None)
    emission = shader_mix.value(shader, "emission")
    strength = float(max(emission.max(), 1.0))
    values = {PrincipledSlot.BASE_COLOR: [*base, 1.0],
              PrincipledSlot.ROUGHNESS: [shader_mix.value(shader, "roughness")],
              PrincipledSlot.METALLIC: [shader_mix.value(shader, "metallic")],
              PrincipledSlot.SPECULAR: [shader_mix.value(shader, "specular")],
              PrincipledSlot.EMISSION_COLOR: [*(emission / strength), 1.0],
              PrincipledSlot.EMISSION_STRENGTH: [strength if emission.any() else 0.0],
              PrincipledSlot.ALPHA: [1.0]}
    for slot, value in values.items():
        result.uniforms[slot] = np.array(value, np.float32)
    parameters = ("base", "roughness", "metallic", "specular", "emission")
    if shader_mix.needs_bake(shader, parameters):
        warnings.append(f"Material '{material.name}': its mixed shaders take values from nodes; "
                        "their own values are exported, mixed")
    return result


def _image(path: str, directory: str):
    """The image at ``path`` (relative to ``directory``): loaded, or a placeholder keeping the path."""
    absolute = os.path.normpath(os.path.join(directory, path.replace("/", os.sep)))
    try:
        return bpy.data.images.load(absolute, check_existing=True), True
    except RuntimeError:  # missing file: keep the path so the texture can be found later
        image = bpy.data.images.new(os.path.basename(absolute) or "texture", 1, 1)
        image.source = "FILE"
        image.filepath = absolute
        return image, False


def import_material(material: Material, directory: str, warnings: list[str]):
    """A new ``bpy.types.Material`` from a GFG material."""
    result = bpy.data.materials.new(material.name)
    if result.node_tree is None:  # Blender < 5.0 creates materials without nodes
        result.use_nodes = True
    nodes = result.node_tree.nodes
    principled = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
    if material.logic != MaterialLogic.PRINCIPLED:
        color = material.uniforms.get(LambertSlot.COLOR)
        if color is not None:
            result.diffuse_color = np.resize(np.r_[color, 1.0, 1.0, 1.0][:4], 4).tolist()
        if principled is not None:
            nodes.remove(principled)
        return result
    if principled is None:
        principled = nodes.new("ShaderNodeBsdfPrincipled")
    for slot, name in PRINCIPLED_INPUTS:
        value = material.uniforms.get(slot)
        if value is None:
            continue
        socket = principled.inputs[name]
        target = socket.default_value
        if hasattr(target, "__len__"):
            socket.default_value = [float(v) for v in value[:len(target)]] + list(target[len(value):])
        else:
            socket.default_value = float(value[0])
    path = material.textures.get(PrincipledSlot.BASE_COLOR)
    if path is not None:
        image, found = _image(path, directory)
        if not found:
            warnings.append(f"Material '{material.name}': texture '{path}' was not found")
        texture = nodes.new("ShaderNodeTexImage")
        texture.image = image
        texture.location = (principled.location.x - 300, principled.location.y)
        result.node_tree.links.new(texture.outputs["Color"], principled.inputs["Base Color"])
    return result

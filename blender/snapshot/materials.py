"""Read Blender materials into ``MaterialData`` (main thread).

The engine needs one colour per material: the Principled BSDF's Base Color
input, or the mean of the Image Texture linked into it. Colours are linear
scene-referred RGB; 8-bit sRGB images are linearised per pixel before averaging.
"""
from __future__ import annotations

import numpy as np

from ...voxgi_addon.scene.snapshot import MaterialData


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted: encoded values in [0, 1] -> linear, same shape, float32."""
    values = np.asarray(values, dtype=np.float32)
    low = values / np.float32(12.92)
    high = ((values + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)
    return np.where(values <= 0.04045, low, high).astype(np.float32)


def image_mean_color(image) -> np.ndarray | None:
    """Mean linear RGB of a ``bpy.types.Image``'s pixels, (3,) float32, or None if it has no pixels.

    ``Image.pixels`` holds float buffers in scene-linear and byte buffers in the image's
    colour space, so only byte images tagged sRGB are converted.
    """
    width, height = image.size
    channels = image.channels
    if width * height == 0 or channels == 0:
        return None
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(-1, channels)
    rgb = pixels[:, :3] if channels >= 3 else np.repeat(pixels[:, :1], 3, axis=1)
    if image.colorspace_settings.name == "sRGB" and not image.is_float:
        rgb = srgb_to_linear(rgb)
    return rgb.mean(axis=0, dtype=np.float64).astype(np.float32)


def _surface_node(node_tree, node_type: str):
    """The node of ``node_type`` feeding the active output's Surface, else the first such node, else None."""
    output = node_tree.get_output_node("ALL")
    if output is not None:
        surface = output.inputs.get("Surface")
        if surface is not None and surface.is_linked:
            node = surface.links[0].from_node
            if node.type == node_type:
                return node
    return next((n for n in node_tree.nodes if n.type == node_type), None)


def _rgb(socket) -> np.ndarray:
    return np.array(socket.default_value[:3], dtype=np.float32)


class MaterialTable:
    """The snapshot's material list, filled as meshes reference materials.

    ``index_of(material)`` returns the index of a ``bpy.types.Material`` in
    ``materials`` (a list of ``MaterialData``), reading it on first use.
    Warnings about approximations (unreadable images, procedural colours) go to
    ``warnings``.
    """

    def __init__(self, warnings: list[str]):
        self.materials: list[MaterialData] = []
        self.warnings = warnings
        self._index: dict[str, int] = {}
        self._image_means: dict[str, np.ndarray | None] = {}

    def index_of(self, material) -> int:
        material = material.original  # evaluated copies share the name but not the image data
        key = material.name_full
        index = self._index.get(key)
        if index is None:
            index = self._index[key] = len(self.materials)
            self.materials.append(self._read(material))
        return index

    def _left_out(self, material, principled) -> None:
        """Say, once per material, what of it the preview does not render yet."""
        tree = material.node_tree
        notes = []
        output = tree.get_output_node("ALL") if tree is not None else None
        if output is not None:
            for socket, what in (("Volume", "its volume shader"), ("Displacement", "displacement")):
                if output.inputs.get(socket) is not None and output.inputs[socket].is_linked:
                    notes.append(what)
        if principled is not None:
            inputs = principled.inputs
            transmission = inputs.get("Transmission Weight")
            if transmission is not None and (transmission.is_linked or transmission.default_value > 0):
                notes.append("transmission (it renders opaque)")
            alpha = inputs.get("Alpha")
            if alpha is not None and (alpha.is_linked or alpha.default_value < 1.0):
                notes.append("transparency (it renders opaque)")
        if notes:
            self.warnings.append(f"Material '{material.name}': the preview leaves out "
                                 f"{', '.join(notes)} for now")

    def _read(self, material) -> MaterialData:
        node_tree = material.node_tree
        principled = None if node_tree is None else _surface_node(node_tree, "BSDF_PRINCIPLED")
        self._left_out(material, principled)
        glow = None if node_tree is None or principled is not None else \
            _surface_node(node_tree, "EMISSION")
        if glow is not None:  # an Emission shader: light, and nothing reflected (Cycles)
            emission = _rgb(glow.inputs["Color"]) * np.float32(glow.inputs["Strength"].default_value)
            return MaterialData(name=material.name_full, base_color=np.zeros(3, np.float32),
                                roughness=1.0, metallic=0.0, specular=0.0,
                                emission=emission.astype(np.float32))
        if principled is None:
            return MaterialData(
                name=material.name_full,
                base_color=np.array(material.diffuse_color[:3], dtype=np.float32),
                roughness=float(material.roughness),
                metallic=float(material.metallic),
                specular=float(material.specular_intensity),
            )
        inputs = principled.inputs
        emission = _rgb(inputs["Emission Color"]) * np.float32(inputs["Emission Strength"].default_value)
        return MaterialData(
            name=material.name_full,
            base_color=self._base_color(material, inputs["Base Color"]),
            roughness=float(inputs["Roughness"].default_value),
            metallic=float(inputs["Metallic"].default_value),
            specular=float(inputs["Specular IOR Level"].default_value),
            emission=emission.astype(np.float32),
        )

    def _base_color(self, material, socket) -> np.ndarray:
        if not socket.is_linked:
            return _rgb(socket)
        node = socket.links[0].from_node
        if node.type == "TEX_IMAGE" and node.image is not None:
            mean = self._image_mean(node.image)
            if mean is not None:
                return mean
            self.warnings.append(
                f"Material '{material.name_full}': image '{node.image.name_full}' has no pixels "
                "(missing file?); using the Base Color value instead"
            )
        else:
            self.warnings.append(
                f"Material '{material.name_full}': Base Color comes from a '{node.name}' node, "
                "which VoxGI cannot evaluate; using the Base Color value instead"
            )
        return _rgb(socket)

    def _image_mean(self, image) -> np.ndarray | None:
        key = image.name_full
        if key not in self._image_means:
            self._image_means[key] = image_mean_color(image)
        return self._image_means[key]

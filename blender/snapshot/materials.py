"""Read Blender materials into ``MaterialData`` and their textures into ``TextureData``
(main thread; docs/gi_pipeline.md "Materials per texel").

The Base Color comes from where the material takes it:

* a value: the socket's ``default_value``;
* an **Image Texture** node (directly, or through Mapping nodes fed by a UV Map node or the
  Texture Coordinate's UV): the image's pixels as a ``TextureData`` (linear: sRGB byte images
  linearised as Blender's colour management does; Non-Color and linear images as they are),
  its interpolation and extension, the Mappings as a UV affine map, sampled per texel through
  the mesh's UV map (the node's, else the active render UV map). A missing or unreadable
  image: a warning and the socket's value;
* anything else (procedural textures, mixes, ramps, an image through other nodes, a surface
  that is not a lone Principled BSDF): **Cycles bakes it** into an image over the mesh's
  active render UV map, per (material, mesh) — the socket routed to an Emission shader (an
  Emit bake) for a Principled BSDF, the Diffuse Color pass (a Diffuse bake) otherwise — in a
  temporary scene with a temporary copy of the mesh and material, everything removed
  afterwards (the user's file is left as it was; ``bakes.py``). Bakes are cached by the node
  tree's content and the mesh's; where no bake can run (off the main thread, during a render
  job), a warning and the socket's value. The live viewport queues its bakes instead (a
  ``bakes.BakeQueue`` given to ``MaterialTable``): the value until its draws have baked them.

The Alpha socket likewise (cut-outs, issue 22 point 2): a value; an Image Texture's Alpha
output (the image's alpha channel, in the 4th channel of its ``TextureData``: one texture for
Base Color and Alpha when both come from the same image node; an image whose Alpha Mode is
None is opaque); anything else baked (an Emit bake of the socket, into a texture's 4th
channel).

Roughness and Metallic from an image (directly — its Color as luminance, or its Alpha — or one
channel through a Separate Color node, as the glTF importer builds them from one
metallic-roughness image) become a parameter texture (channel 0 roughness, channel 1
metallic), and the material is followed in the list by its ``textures.PARAM_VARIANTS``
variants at quantized values, which surface points shade with per texel. Both sockets from
two different images, or from other nodes: the images' means / the value, with a warning.

Emission Color (a Principled BSDF's, or an Emission shader's Color) likewise: a value, an Image
Texture's Color per texel (``emission_texture``, times ``emission_strength``), anything else
baked by Cycles as the Base Color is (Principled BSDF only); ``emission`` is the mean × the
strength.

A material whose Principled BSDF sits inside a node group (nested too) is read through the
groups as the flat one would be (``node_groups``); its bakes route through copies of them.

A Base Color that varies per object through Object Info › Random or Color (a Color Ramp, Mix
or Hue/Saturation of them: ``object_random``) is not baked: its entry holds the colour's mean
over Random (on a white object), and ``object_material`` gives each object a variant of it at
the object's own Random and Color (``ObjectData.materials``), as Cycles colours each copy of a
scattered mesh.

Normal: a tangent-space Normal Map node fed by an Image Texture's Color (as the glTF importer
builds normal maps) gives ``normal_texture`` and ``normal_strength``; other normal inputs
(Bump, object- or world-space maps) are left out with a note.
"""
from __future__ import annotations

import dataclasses
import hashlib
import threading

import bpy
import numpy as np

from ...voxgi_addon.scene.snapshot import MaterialData, TextureData
from ...voxgi_addon.scene.textures import PARAM_VARIANTS, srgb_to_linear, variant_values, within_max_size
from . import animated, bakes, shader_mix, udim
from .auto_uvs import polygon_uvs
from .left_out import material_notes
from .node_groups import route_to_emission, surface_node
from .object_random import ObjectInputs, object_base_color, object_random
from .reads import count
from .world_map import (
    _euler_matrix,
    _follow,
    _image_key,
    _image_pixels,
    _NeedsBake,
    _tree_key,
    shows_moving_images,
)

MAX_VARIANT_MATERIALS = 96  # materials with Roughness / Metallic per texel (each adds 64 rows)
# An object's Random is taken to 1/RANDOM_STEPS (a Base Color by Random then has at most
# RANDOM_STEPS + 1 variants and evaluations, whatever the number of objects: 2,000 copies
# cost the snapshot 130 ms evaluated one by one); a ramp's colour moves by at most 1/512 of
# its range
RANDOM_STEPS = 256
COLOR_STEPS = 1024  # an object's Color, each channel, likewise (8-bit colours stay apart)
EMISSION_SHADER = "Emission shader"  # an Emission surface's own light (Color × Strength) baked
CUTOUT_FAC = "Cut-out Fac"  # the baked Fac of a Mix Shader of a Transparent BSDF and this one
AUTO_UVS = "VoxGI Auto UVs"  # the UV map of a bake over a layout of the mesh's polygons
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)  # Cycles' colour → float (Rec.709)
LINEAR_SPACES = ("Linear Rec.709", "scene_linear", "Non-Color", "Linear CIE-XYZ E")
SCENE_LINEAR = ("Linear Rec.709", "scene_linear")
MAPPING_TYPES = ("POINT", "TEXTURE", "VECTOR")
_BAKED: dict[str, TextureData] = {}
_DERIVED: dict[tuple[str, str], object] = {}  # (bake key, what) → ``_derived``


def bake_count() -> int:
    """How many Cycles bakes of a material socket this session ran."""
    return bakes.bake_count()


def clear_bake_cache() -> None:
    _BAKED.clear()
    _DERIVED.clear()
    _IMAGES.clear()


@bpy.app.handlers.persistent
def _clear_on_load(*_args) -> None:
    clear_bake_cache()


def image_mean_color(image) -> np.ndarray | None:
    """Mean linear RGB of a ``bpy.types.Image``'s pixels, (3,) float32, or None if it has no pixels.

    ``Image.pixels`` holds float buffers in scene-linear and byte buffers in the image's
    colour space, so only byte images tagged sRGB are converted.
    """
    rgb = image_rgb(image)
    return None if rgb is None else rgb.reshape(-1, 3).mean(axis=0, dtype=np.float64).astype(np.float32)


def _srgb_bytes(image) -> bool:
    """Is ``image`` a byte image in sRGB (its pixels the encoded bytes, which Cycles blends
    before decoding: ``TextureData.srgb_bytes``)?"""
    return image.colorspace_settings.name == "sRGB" and not image.is_float


def image_rgb(image) -> np.ndarray | None:
    """(H, W, 3) float32 linear RGB of an image (row 0 = bottom; a UDIM image's tiles in one
    atlas, ``udim``), None without pixels; raises ``_NeedsBake`` for colour spaces only Blender
    can convert."""
    if image.source == "TILED":
        return udim.atlas(image, image_rgb)
    if image.source not in ("FILE", "GENERATED"):
        raise _NeedsBake(f"the image '{image.name}' is a {image.source.lower()}")
    pixels = _image_pixels(image)
    if pixels is None:
        return None
    rgb = np.ascontiguousarray(pixels[..., :3], np.float32)
    space = image.colorspace_settings.name
    if space in LINEAR_SPACES and (space == "Non-Color" or
                                   bpy.data.colorspace.working_space in SCENE_LINEAR):
        return rgb
    if bpy.data.colorspace.working_space not in SCENE_LINEAR:
        raise _NeedsBake(f"the file's working colour space is {bpy.data.colorspace.working_space}")
    if _srgb_bytes(image):
        return srgb_to_linear(rgb)  # byte pixels hold the encoded values (docs "World")
    if space == "sRGB":
        return rgb  # float buffers are made scene-linear on load
    raise _NeedsBake(f"the image '{image.name}' is in the colour space '{space}'")


def _mapping_affine(node) -> np.ndarray:
    """(3, 4) affine matrix of a Mapping node on points (Cycles' evaluation, docs "World")."""
    for name in ("Location", "Rotation", "Scale"):
        socket = node.inputs.get(name)
        if socket is not None and socket.is_linked:
            raise _NeedsBake(f"the Mapping node '{node.name}' has a linked {name}")
    kind = node.vector_type
    if kind not in MAPPING_TYPES:
        raise _NeedsBake(f"the Mapping node '{node.name}' is of type {kind}")
    rotation = _euler_matrix(node.inputs["Rotation"].default_value)
    scale = np.array(node.inputs["Scale"].default_value, np.float64)
    location = np.array(node.inputs["Location"].default_value, np.float64) \
        if kind in ("POINT", "TEXTURE") else np.zeros(3)
    out = np.zeros((3, 4))
    if kind == "TEXTURE":
        inverse = np.divide(1.0, scale, out=np.zeros(3), where=scale != 0)
        out[:, :3] = inverse[:, None] * rotation.T
        out[:, 3] = -out[:, :3] @ location
    else:
        out[:, :3] = rotation * scale[None, :]
        out[:, 3] = location
    return out


def uv_source(node) -> tuple[str, np.ndarray]:
    """(UV map name or "" for the active render one, (2, 3) affine map of (u, v, 1)) of an
    Image Texture node's Vector input; raises ``_NeedsBake`` for other coordinates."""
    matrix = np.eye(4)[:3]
    socket = node.inputs.get("Vector")
    if socket is None or not socket.is_linked:
        return "", np.eye(2, 3)
    while True:
        if socket is None or not socket.is_linked:
            raise _NeedsBake("a Mapping node without a vector input")
        source, output = _follow(socket)
        if source is None:
            raise _NeedsBake("a muted link in front of the image")
        if source.type == "MAPPING":
            step = _mapping_affine(source)
            matrix = np.concatenate([step[:, :3] @ matrix[:, :3],
                                     (step[:, :3] @ matrix[:, 3] + step[:, 3])[:, None]], axis=1)
            socket = source.inputs.get("Vector")
            continue
        if source.type == "UVMAP" and not source.from_instancer:
            name = source.uv_map
            break
        if source.type == "TEX_COORD" and output.identifier == "UV" and not source.from_instancer:
            name = ""
            break
        raise _NeedsBake(f"the image's coordinates come from '{source.name}'")
    # (u, v, 0): the image reads x and y of the vector
    return name, np.stack([matrix[:2, 0], matrix[:2, 1], matrix[:2, 3]], axis=1)


def _rgb(socket) -> np.ndarray:
    return np.array(socket.default_value[:3], dtype=np.float32)


def _value(socket) -> np.float32:
    return np.float32(socket.default_value)


_IMAGES: dict[tuple, np.ndarray | None] = {}
MAX_IMAGES = 16


def _cached_image_rgb(image) -> np.ndarray | None:
    return _cached_image(image)[0]


def _cached_image(image) -> tuple[np.ndarray | None, str]:
    """(``image_rgb`` of an image, a content key of it), kept between snapshots while the
    image is unchanged: a file image by its path and modification time, a packed one by its
    packed bytes (each snapshot of a live viewport would otherwise read every pixel again); an
    image edited in this session (``is_dirty``) is read, and its pixels hashed, every time."""
    if image.is_dirty or image.source not in ("FILE", "GENERATED", "TILED"):
        rgb = image_rgb(image)
        content = None if rgb is None else hashlib.blake2b(rgb.tobytes(), digest_size=16).hexdigest()
        return rgb, _digest(image.name_full, content)
    packed = image.packed_file
    if image.source == "TILED":
        content = udim.content_key(image)
    elif packed is not None:
        content = hashlib.blake2b(bytes(packed.data), digest_size=16).hexdigest()
    elif image.source == "FILE":
        content = _image_key(image)
    else:  # a generated image nobody painted: its generator's settings
        content = (image.generated_type, tuple(image.generated_color), image.use_generated_float)
    key = (image.name_full, tuple(image.size), image.colorspace_settings.name,
           bpy.data.colorspace.working_space, content)
    if key not in _IMAGES:
        while len(_IMAGES) >= MAX_IMAGES:
            _IMAGES.pop(next(iter(_IMAGES)))
        _IMAGES[key] = image_rgb(image)
    return _IMAGES[key], _digest(key)


def _texels_mean(pixels: np.ndarray, image) -> np.ndarray:
    """(C,) float32 mean of an image's texels (a UDIM atlas': of its tiles alone)."""
    if image.source == "TILED":
        return udim.mean_over_tiles(pixels, image).astype(np.float32)
    return pixels.reshape(-1, pixels.shape[-1]).mean(axis=0).astype(np.float32)


def _digest(*values) -> str:
    return hashlib.blake2b(repr(values).encode(), digest_size=16).hexdigest()


class Surface:
    """The mesh a material is read for (its textures are baked over this mesh's UV map).

    key : the MeshData key; obj_eval : the evaluated object; mesh : its evaluated mesh
    (``Object.to_mesh()``, valid while the snapshot reads it); slot_materials : its slots'
    materials (``bpy.types.Material`` or None); digest : content key of the triangles and UVs
    (what a bake depends on besides the node tree); has_uvs : the mesh has a UV map.
    auto_uvs : (L, 2) per-loop UVs of a layout of the polygons (``use_auto_uvs``) that a bake
    was made over — the mesh has no UV map, or its UVs leave the UV square — which the
    snapshot's triangles of that material read too; None."""

    auto_uvs = None
    uvs_in_square = True  # do the mesh's UVs stay in [0, 1]² (where a bake writes)?

    def __init__(self, key: str, obj_eval, mesh, slot_materials: list, digest: str,
                 has_uvs: bool):
        self.key, self.obj_eval, self.mesh, self.slot_materials = key, obj_eval, mesh, slot_materials
        self.digest, self.has_uvs = digest, has_uvs

    def use_auto_uvs(self) -> None:
        """Lay the mesh's polygons out in the UV square (``auto_uvs.polygon_uvs``), once."""
        if self.auto_uvs is None:
            self.auto_uvs = polygon_uvs(self.mesh)


class MaterialTable:
    """The snapshot's material list, filled as meshes reference materials.

    ``index_of(material, surface)`` returns the index of a ``bpy.types.Material`` in
    ``materials`` (a list of ``MaterialData``), reading it on first use; a material whose Base
    Color Cycles must bake gets one entry per mesh (``surface``). ``textures`` collects the
    ``TextureData`` the materials sample; ``uv_map(index)`` names the UV map a material's
    texture reads ("" = the active render one). Warnings about approximations (unreadable
    images, what cannot be baked) go to ``warnings``; what of a material the preview leaves
    out (transmission, volumes …) goes to ``notes`` by material name, which the snapshot says
    per object (``left_out``).
    """

    def __init__(self, warnings: list[str], bake: bool | None = None,
                 queue: bakes.BakeQueue | None = None, frame: int = 1):
        self.frame = int(frame)  # the scene's frame (what an image sequence or movie shows)
        self.materials: list[MaterialData] = []
        self.textures: list[TextureData] = []
        self.warnings = warnings
        self._bake = bake
        self._queue = queue  # the live viewport's: bakes are queued, not run (``_baked_socket``)
        self._index: dict[str, int] = {}
        self._read_cache: dict[str, tuple[MaterialData, object, str]] = {}
        self._sources: dict[str, object] = {}  # name → what is read: the user's or the copy
        self._uv_maps: dict[int, str] = {}
        self._texture_index: dict[str, int] = {}
        self._warned: set[str] = set()
        self._variant_materials = 0
        self.notes: dict[str, list[str]] = {}  # material name → what the preview leaves out
        # material name → (its Base Color by an object's ObjectInputs, whether it reads Color)
        self._by_object: dict[str, tuple] = {}
        self._object_variants: dict[tuple, int] = {}  # (index, colour) → variant's index
        self._object_steps: dict[tuple, int] = {}  # (index, step of the inputs) → its material

    def _warn(self, text: str) -> None:
        if text not in self._warned:
            self._warned.add(text)
            self.warnings.append(text)

    def uv_map(self, index: int) -> str:
        return self._uv_maps.get(index, "")

    def index_of(self, material, surface: Surface | None = None) -> int:
        # an animated material from the depsgraph's copy (its values at the depsgraph's frame:
        # an animation render's), any other from the user's datablock (decided once a name)
        name = material.original.name_full
        source = self._sources.get(name)
        if source is None:
            source = self._sources[name] = material if animated.reads_evaluated(material) \
                else material.original
        material = material.original
        if name not in self._read_cache:
            self._read_cache[name] = self._read(source)
        data, bake, uv_map = self._read_cache[name]
        key = name if bake is None else f"{name} @ {surface.key if surface else ''}"
        index = self._index.get(key)
        if index is None:
            if bake is not None:
                data, uv_map = self._baked(source, data, bake, surface, uv_map)
            index = self._index[key] = len(self.materials)
            if data.param_texture >= 0 and self._variant_materials >= MAX_VARIANT_MATERIALS:
                self._warn(f"Material '{data.name}': more than {MAX_VARIANT_MATERIALS} "
                           "materials take Roughness / Metallic per texel; this one takes the "
                           "image's means")
                data = dataclasses.replace(data, param_texture=-1)
            if data.param_texture >= 0:  # its variants follow it (textures.PARAM_VARIANTS)
                self._variant_materials += 1
                data = dataclasses.replace(data, param_variants=index + 1)
            self.materials.append(data)
            self._uv_maps[index] = uv_map
            if data.param_texture >= 0:
                for k in range(PARAM_VARIANTS):
                    rough, metal = variant_values(k)
                    self.materials.append(dataclasses.replace(
                        data, name=f"{data.name} [roughness {rough:.3f}, metallic {metal:.3f}]",
                        roughness=float(rough), metallic=float(metal), param_texture=-1,
                        param_variants=-1))
        return index

    @property
    def varies_by_object(self) -> bool:
        """Does any material read so far take its Base Color from Object Info › Random or
        Color?"""
        return bool(self._by_object)

    @property
    def reads_object_color(self) -> bool:
        """Does any material read so far take its Base Color from Object Info › Color?"""
        return any(reads for _, reads in self._by_object.values())

    def varies(self, index: int) -> bool:
        """Does material ``index`` take its Base Color from Object Info (a variant per object,
        ``object_material``)?"""
        data = self.materials[index] if 0 <= index < len(self.materials) else None
        return data is not None and data.name in self._by_object and data.param_texture < 0

    def object_material(self, index: int, inputs: ObjectInputs) -> int:
        """The material an object whose Object Info gives ``inputs`` (its Random, its Color)
        shades with where its mesh uses material ``index``: a variant with the Base Color at
        its inputs (one per colour) where the material's Base Color follows them, else
        ``index``."""
        data = self.materials[index] if 0 <= index < len(self.materials) else None
        by_object = None if data is None else self._by_object.get(data.name)
        colour_steps = None if by_object is None or not by_object[1] else \
            tuple(round(float(c) * COLOR_STEPS) for c in inputs.color[:4])
        step = (index, round(float(inputs.random) * RANDOM_STEPS), colour_steps)
        known = self._object_steps.get(step)
        if known is not None:
            return known
        if by_object is None or data.param_texture >= 0:
            self._object_steps[step] = index
            return index
        colour = by_object[0](ObjectInputs(
            step[1] / RANDOM_STEPS, inputs.color if colour_steps is None else
            tuple(c / COLOR_STEPS for c in colour_steps)))
        key = (index, tuple(np.round(colour * 4096).astype(np.int64)))
        variant = self._object_variants.get(key)
        if variant is None:
            variant = self._object_variants[key] = len(self.materials)
            self.materials.append(dataclasses.replace(
                data, name=f"{data.name} [Object Info: {', '.join(f'{c:.3f}' for c in colour)}]",
                base_color=colour.astype(np.float32)))
            self._uv_maps[variant] = self._uv_maps.get(index, "")
        self._object_steps[step] = variant
        return variant

    def _add_texture(self, texture: TextureData) -> int:
        key = _digest(texture.key, texture.interpolation, texture.extension,
                      np.asarray(texture.uv_transform).tobytes())
        if key not in self._texture_index:
            self._texture_index[key] = len(self.textures)
            self.textures.append(texture)
        return self._texture_index[key]

    def _left_out(self, material) -> None:
        """Note what of ``material`` the preview does not render yet (``left_out
        .material_notes``), said per object that uses it (``notes``)."""
        self.notes[material.name_full] = material_notes(material)

    def _read(self, material) -> tuple[MaterialData, object, str]:
        """(MaterialData, what to bake per mesh (None, or (mode, socket name)), UV map)."""
        count("materials")
        node_tree = material.node_tree
        principled = None if node_tree is None else surface_node(node_tree, "BSDF_PRINCIPLED")
        self._left_out(material)
        mixed = None if node_tree is None else shader_mix.read(node_tree)
        if mixed is not None:  # a Mix Shader of BSDFs, a Glossy BSDF: one mixed Principled
            return self._mixed(material, mixed)
        glow = None if node_tree is None or principled is not None else \
            surface_node(node_tree, "EMISSION")
        if glow is not None:  # an Emission shader: light, and nothing reflected (Cycles)
            strength = np.float32(glow.inputs["Strength"].default_value)
            colour, texture, bake, uv_map = self._emission(material, glow.inputs["Color"])
            if bake is not None or glow.inputs["Strength"].is_linked:
                # Color or Strength from nodes: the surface's own emission baked by Cycles
                # (Color × Strength per texel), its values meanwhile
                return MaterialData(name=material.name_full, base_color=np.zeros(3, np.float32),
                                    roughness=1.0, metallic=0.0, specular=0.0,
                                    emission=(colour * strength).astype(np.float32),
                                    emission_strength=1.0), (("EMIT", EMISSION_SHADER),), ""
            return MaterialData(name=material.name_full, base_color=np.zeros(3, np.float32),
                                roughness=1.0, metallic=0.0, specular=0.0,
                                emission=(colour * strength).astype(np.float32),
                                emission_texture=-1 if texture is None else
                                self._add_texture(texture),
                                emission_strength=float(strength)), None, uv_map
        if principled is None:
            data = MaterialData(
                name=material.name_full,
                base_color=np.array(material.diffuse_color[:3], dtype=np.float32),
                roughness=float(material.roughness),
                metallic=float(material.metallic),
                specular=float(material.specular_intensity),
            )
            output = None if node_tree is None else node_tree.get_output_node("CYCLES")
            surface = None if output is None else output.inputs.get("Surface")
            if surface is not None and surface.is_linked:
                # another surface (a Diffuse BSDF, a Mix Shader …): its diffuse colour, baked;
                # no glossy layer of our own
                data = MaterialData(name=data.name, base_color=data.base_color, roughness=1.0,
                                    metallic=0.0, specular=0.0)
                return data, (("DIFFUSE", "Surface"),), ""
            return data, None, ""
        inputs = principled.inputs
        glow_strength = np.float32(inputs["Emission Strength"].default_value)
        glow, glow_texture, glow_bake, glow_uv = self._emission(material, inputs["Emission Color"])
        if inputs["Emission Strength"].is_linked:
            # a Strength from nodes (a mask, a falloff): the surface's emission baked whole,
            # Color × Strength per texel (as an Emission shader's built of nodes); the values
            # until then
            glow, glow_strength = glow * glow_strength, np.float32(1.0)
            glow_texture, glow_bake, glow_uv = None, ("EMIT", EMISSION_SHADER), ""
        emission = glow * glow_strength
        by_object = object_base_color(material)
        if by_object is not None:  # per object (``object_material``); here its mean colour
            self._by_object[material.name_full] = by_object
            base = np.mean([by_object[0](ObjectInputs(r)) for r in np.linspace(0.0, 1.0, 33)],
                           axis=0).astype(np.float32)
            texture, bake, uv_map = None, None, ""
        else:
            base, texture, bake, uv_map = self._base_color(material, inputs["Base Color"])
        params, params_uv = self._params(material, inputs)
        if params is not None:
            roughness, metallic = (float(params.pixels[..., c].mean()) for c in (0, 1))
            if texture is None:
                uv_map = params_uv
        else:
            roughness = float(self._socket_mean(material, inputs["Roughness"], _value))
            metallic = float(self._socket_mean(material, inputs["Metallic"], _value))
        alpha_socket = inputs.get("Alpha")
        mix = _transparent_mix(node_tree, principled)
        if mix is not None and alpha_socket is not None and not alpha_socket.is_linked and \
                alpha_socket.default_value >= 1.0:
            alpha_socket = mix  # Mix Shader (Transparent BSDF, this BSDF): its Fac
        alpha, alpha_texture, alpha_bake, alpha_uv = self._alpha(material, alpha_socket, texture)
        if alpha_texture is not None and texture is None:
            uv_map = alpha_uv
        elif alpha_texture is not None and alpha_texture is not texture and alpha_uv != uv_map:
            self._warn(f"Material '{material.name_full}': its Base Color and Alpha images read "
                       "different UV maps; the Alpha is read through the Base Color's")
        normal, strength, normal_uv = self._normal_map(material, inputs.get("Normal"))
        if normal is not None and texture is None and params is None and alpha_texture is None:
            uv_map = normal_uv
        if glow_texture is not None and texture is None and params is None and \
                alpha_texture is None and normal is None:
            uv_map = glow_uv
        elif glow_texture is not None and glow_uv != uv_map:
            self._warn(f"Material '{material.name_full}': its Emission Color image reads another "
                       "UV map than its other images; it is read through theirs")
        transmission, ior = np.zeros(3, np.float32), 1.5
        socket = inputs.get("Transmission Weight")
        weight = 0.0 if socket is None else \
            float(np.clip(self._socket_mean(material, socket, _value), 0.0, 1.0)) * (1.0 - metallic)
        if weight > 0.0:  # the glass lobe (preview.transmission: a thin surface)
            transmission = (np.asarray(base, np.float32) * weight).astype(np.float32)
            base = (np.asarray(base, np.float32) * (1.0 - weight)).astype(np.float32)
            ior = float(inputs["IOR"].default_value) if "IOR" in inputs else 1.5
            if texture is not None:
                self._warn(f"Material '{material.name_full}': its transmission tint is its Base "
                           "Color image's mean colour")
                if weight >= 1.0 - 1e-6:  # nothing diffuse left to texture
                    texture, bake = None, None
        bakes = tuple(b for b in (bake, alpha_bake, glow_bake) if b is not None)
        data = MaterialData(
            name=material.name_full,
            base_color=base,
            roughness=roughness,
            metallic=metallic,
            specular=float(inputs["Specular IOR Level"].default_value),
            emission=emission.astype(np.float32),
            base_color_texture=-1 if texture is None else self._add_texture(texture),
            alpha=float(alpha),
            alpha_texture=-1 if alpha_texture is None else self._add_texture(alpha_texture),
            param_texture=-1 if params is None else self._add_texture(params),
            normal_texture=-1 if normal is None else self._add_texture(normal),
            normal_strength=strength,
            emission_texture=-1 if glow_texture is None else self._add_texture(glow_texture),
            emission_strength=float(glow_strength),
            transmission=transmission,
            ior=ior,
        )
        return data, bakes or None, uv_map

    def _mixed(self, material, shader):
        """(MaterialData, what to bake, UV map) of a shader mix (``shader_mix``): its mixed
        parameters, the Base Color and the Roughness / Metallic / Specular baked by Cycles
        where a Fac or an input comes from nodes, and the leaves' normal map where they share
        one."""
        if shader_mix.needs_bake(shader, ("emission",)):
            self._warn(f"Material '{material.name_full}': the emission of its mixed shaders "
                       "comes from nodes the preview does not evaluate there yet; using their values")
        socket, several = shader_mix.normal_socket(shader)
        if several:
            self._warn(f"Material '{material.name_full}': its mixed shaders take their normals "
                       "from different nodes; the preview leaves their normal maps out")
        normal, strength, uv_map = self._normal_map(material, socket)
        data = MaterialData(
            name=material.name_full,
            base_color=np.clip(shader_mix.value(shader, "base"), 0.0, None).astype(np.float32),
            roughness=float(shader_mix.value(shader, "roughness")),
            metallic=float(shader_mix.value(shader, "metallic")),
            specular=float(shader_mix.value(shader, "specular")),
            emission=shader_mix.value(shader, "emission").astype(np.float32),
            normal_texture=-1 if normal is None else self._add_texture(normal),
            normal_strength=strength)
        bakes = []
        if shader_mix.needs_bake(shader, ("base",)):
            bakes.append(("EMIT", shader_mix.BASE))
        if shader_mix.needs_bake(shader, ("roughness", "metallic", "specular")):
            bakes.append(("EMIT", shader_mix.PARAMS))
        if bakes and uv_map:  # the bakes go over the render UV map, the normal map its own
            self._warn(f"Material '{material.name_full}': its normal map reads another UV map "
                       "than its baked mix; it is read through the render one")
        return data, tuple(bakes) or None, "" if bakes else uv_map

    def _emission(self, material, socket):
        """(mean colour (3,), TextureData or None, what to bake or None, UV map) of an Emission
        Color socket: its value when unlinked; an Image Texture's Color (directly or through
        Mapping nodes) per texel; anything else baked by Cycles (an Emit bake of the socket, as
        the Base Color's)."""
        if not socket.is_linked:
            return _rgb(socket), None, None, ""
        name = material.name_full
        try:
            node, output = _follow(socket)
            if node is None:
                return _rgb(socket), None, None, ""
            if node.type != "TEX_IMAGE" or output.identifier != "Color":
                raise _NeedsBake(f"{socket.name} comes from '{node.name}'")
            if node.image is None:
                self._warn(f"Material '{name}': the Image Texture node '{node.name}' has no "
                           f"image; using the {socket.name} value instead")
                return _rgb(socket), None, None, ""
            texture, uv_map = self._image(material, node)
            if texture is None:
                self._warn(f"Material '{name}': image '{node.image.name_full}' has no pixels "
                           f"(missing or unreadable file?); using the {socket.name} value instead")
                return _rgb(socket), None, None, ""
            mean = _texels_mean(texture.pixels[..., :3], node.image)
            return mean, texture, None, uv_map
        except _NeedsBake:
            return _rgb(socket), None, ("EMIT", socket.name), ""

    def _socket_mean(self, material, socket, value):
        """A Roughness or Metallic socket's value: its own when unlinked; the
        mean of the image feeding it (directly, or one channel through a Separate Color node,
        as the glTF importer builds them) with a warning that it is not read per texel yet;
        else its own value with a warning."""
        if not socket.is_linked:
            return value(socket)
        try:
            node, output = _follow(socket)
        except _NeedsBake:
            node = output = None
        channel = None
        if node is not None and node.type in ("SEPRGB", "SEPARATE_COLOR", "SEPARATE_RGB"):
            channel = {"R": 0, "G": 1, "B": 2, "Red": 0, "Green": 1, "Blue": 2}.get(
                output.identifier, {"R": 0, "G": 1, "B": 2}.get(output.name))
            try:
                node, output = _follow(node.inputs[0])
            except _NeedsBake:
                node = None
        name = f"Material '{material.name_full}': {socket.name}"
        if node is not None and node.type == "TEX_IMAGE" and node.image is not None and \
                output is not None and output.identifier == "Color":
            try:
                rgb = _cached_image_rgb(node.image)
            except _NeedsBake:
                rgb = None
            if rgb is not None:
                mean = _texels_mean(rgb, node.image)
                self._warn(f"{name} comes from the image '{node.image.name_full}': the "
                           "preview uses its mean (Roughness / Metallic from two images are not "
                           "read per texel yet)")
                if np.ndim(value(socket)) == 0:
                    return np.float32(mean[channel] if channel is not None else mean.mean())
                return mean.astype(np.float32)
        self._warn(f"{name} comes from nodes the preview does not evaluate yet; using its "
                   "value")
        return value(socket)

    def _base_color(self, material, socket):
        """(value (3,), TextureData or None, what to bake or None, UV map name)."""
        if not socket.is_linked:
            return _rgb(socket), None, None, ""
        try:
            node, output = _follow(socket)
            if node is None:
                return _rgb(socket), None, None, ""
            if node.type != "TEX_IMAGE":
                raise _NeedsBake(f"Base Color comes from a '{node.name}' node")
            if output.identifier != "Color":
                raise _NeedsBake(f"Base Color comes from the image's {output.name} output")
            if node.image is None:
                self._warn(f"Material '{material.name_full}': the Image Texture node "
                           f"'{node.name}' has no image; using the Base Color value instead")
                return _rgb(socket), None, None, ""
            texture, uv_map = self._image(material, node, _alpha_node(socket.node) == node)
            if texture is None:
                self._warn(
                    f"Material '{material.name_full}': image '{node.image.name_full}' has no "
                    "pixels (missing or unreadable file?); using the Base Color value instead")
                return _rgb(socket), None, None, ""
            mean = _texels_mean(texture.pixels[..., :3], node.image)
            return mean, texture, None, uv_map
        except _NeedsBake:
            return _rgb(socket), None, ("EMIT", socket.name), ""

    def _params(self, material, inputs):
        """(TextureData of Roughness (channel 0) and Metallic (channel 1) per texel, the UV map
        it reads), or (None, "") when neither comes from an image, or they come from two image
        nodes or other nodes (``_socket_mean`` then takes means and warns)."""
        sources = {}
        for name in ("Roughness", "Metallic"):
            socket = inputs.get(name)
            if socket is None or not socket.is_linked:
                continue
            found = _image_channel(socket)
            if found is None:
                return None, ""
            sources[name] = found
        if not sources or len({node.name for node, _ in sources.values()}) > 1:
            return None, ""
        node = next(iter(sources.values()))[0]
        try:
            texture, uv_map = self._image(material, node, True)
        except _NeedsBake:
            return None, ""
        if texture is None:
            return None, ""
        rgba = texture.pixels
        params = np.zeros(rgba.shape[:2] + (4,), np.float32)
        params[..., 3] = 1.0
        for c, name in enumerate(("Roughness", "Metallic")):
            if name not in sources:
                params[..., c] = float(inputs[name].default_value)
                continue
            channel = sources[name][1]
            params[..., c] = rgba[..., :3] @ LUMINANCE if channel is None else rgba[..., channel]
        key = _digest(texture.key, tuple(sources[n][1] if n in sources else
                                         float(inputs[n].default_value)
                                         for n in ("Roughness", "Metallic")))
        return TextureData(name=f"{texture.name} (roughness, metallic)", pixels=params,
                           interpolation=texture.interpolation, extension=texture.extension,
                           uv_transform=texture.uv_transform, key=key), uv_map

    def _normal_map(self, material, socket):
        """(TextureData of a tangent-space normal map or None, its Strength, its UV map)."""
        if socket is None or not socket.is_linked:
            return None, 1.0, ""
        name = material.name_full
        try:
            node, _ = _follow(socket)
            if node is None:
                return None, 1.0, ""
            if node.type != "NORMAL_MAP" or node.space != "TANGENT":
                raise _NeedsBake(f"its Normal comes from '{node.name}'")
            strength = node.inputs["Strength"]
            if strength.is_linked:
                raise _NeedsBake("its Normal Map's Strength is linked")
            colour = node.inputs["Color"]
            if not colour.is_linked:
                return None, 1.0, ""
            image, output = _follow(colour)
            if image is None:
                return None, 1.0, ""
            if image.type != "TEX_IMAGE" or output.identifier != "Color" or image.image is None:
                raise _NeedsBake(f"its Normal Map's Color comes from '{image.name}'")
            texture, uv_map = self._image(material, image)
            if texture is None:
                self._warn(f"Material '{name}': normal map image '{image.image.name_full}' has "
                           "no pixels (missing or unreadable file?); the normals are not mapped")
                return None, 1.0, ""
            return texture, float(strength.default_value), node.uv_map or uv_map
        except _NeedsBake as why:
            self._warn(f"Material '{name}': {why}; the preview leaves its normal map out")
            return None, 1.0, ""

    def _alpha(self, material, socket, base_texture):
        """(value, TextureData whose 4th channel is the Alpha or None, what to bake or None,
        the UV map its image reads) of a Principled BSDF's Alpha socket; the Base Color's
        texture itself when it is the same image node's."""
        if socket is None:
            return 1.0, None, None, ""
        value = float(np.clip(socket.default_value, 0.0, 1.0))
        if not socket.is_linked:
            return value, None, None, ""
        try:
            node, output = _follow(socket)
            if node is None:
                return value, None, None, ""
            if node.type != "TEX_IMAGE" or output.identifier != "Alpha":
                raise _NeedsBake(f"Alpha comes from '{node.name}'")
            if node.image is None or node.image.alpha_mode == "NONE":
                return 1.0, None, None, ""  # no image, or one whose alpha Cycles ignores
            texture, uv_map = self._image(material, node, True)
            if texture is None:
                self._warn(f"Material '{material.name_full}': image '{node.image.name_full}' "
                           "has no pixels (missing or unreadable file?); using the Alpha value")
                return value, None, None, ""
            if base_texture is not None and base_texture.key == texture.key and \
                    np.array_equal(base_texture.uv_transform, texture.uv_transform):
                return value, base_texture, None, uv_map  # one RGBA texture for both
            return value, texture, None, uv_map
        except _NeedsBake:
            if socket.node.type != "BSDF_PRINCIPLED":  # the cut-out Mix Shader's Fac
                return value, None, ("EMIT", CUTOUT_FAC), ""
            return value, None, ("EMIT", socket.name), ""

    def _image(self, material, node, with_alpha: bool = False):
        """``_image_texture`` of an Image Texture node, saying which UDIM tiles of its image
        have no pixels (missing files: drawn magenta there, as Cycles draws them)."""
        texture, uv_map = _image_texture(node, with_alpha)
        if texture is not None and node.image.source == "TILED":
            missing = udim.missing_tiles(node.image)
            if missing:
                numbers = ", ".join(str(n) for n in missing)
                self._warn(f"Material '{material.name_full}': image '{node.image.name_full}' has "
                           f"no file for UDIM tile{'s' if len(missing) > 1 else ''} {numbers}; "
                           "drawn magenta there, as Cycles draws it")
        return texture, uv_map

    # ------------------------------------------------------------------ bakes

    def _baked(self, material, data: MaterialData, bakes, surface: Surface | None,
               uv_map: str) -> tuple[MaterialData, str]:
        """(``data`` with its sockets ``bakes`` ((mode, socket) pairs) baked by Cycles, the UV
        map its triangles read): over ``surface``'s UV map, or over a layout of its polygons
        (``AUTO_UVS``: ``auto_uvs``) where it has none, or where its UVs leave the UV square
        (tiling, UDIM tiles: a bake writes the square alone) and the material reads no image
        through them itself; ``data`` with a warning where no bake can run."""
        auto = surface is not None and surface.obj_eval is not None and (
            not surface.has_uvs or (not surface.uvs_in_square and not _reads_images(data)))
        if auto:
            surface.use_auto_uvs()
        for bake in bakes:
            data = self._baked_socket(material, data, bake, surface, auto)
        return data, AUTO_UVS if auto else uv_map

    def _baked_socket(self, material, data: MaterialData, bake, surface,
                      auto: bool = False) -> MaterialData:
        mode, socket = bake
        what = socket if mode == "EMIT" else "surface"
        name = material.name_full
        if surface is None or surface.obj_eval is None:
            self._warn(f"Material '{name}': its {what} needs a bake by Cycles, which needs a "
                       "mesh; using its value")
            return data
        users = getattr(getattr(surface.obj_eval.original, "data", None), "users", 0)
        if users > MAX_OWN_BAKES and reads_its_object(material):
            self._warn(f"Material '{name}': its {what} depends on each object (Object Info, "
                       f"its place), but the {users} objects sharing its mesh are baked once, "
                       f"for the first (at most {MAX_OWN_BAKES} are baked each for itself)")
        key = _digest(_tree_key(material.node_tree), mode, socket, surface.digest, auto,
                      bakes.BAKE_SIZE, bakes.BAKE_SAMPLES,
                      tuple(np.array(surface.obj_eval.matrix_world).ravel())
                      if _uses_object_space(material.node_tree) else None,
                      _object_info(surface.obj_eval) if _uses_node(material.node_tree, "OBJECT_INFO")
                      else None,
                      self.frame if shows_moving_images(material.node_tree) else None)
        texture = _BAKED.get(key)
        if texture is None and self._queue is not None:
            # the live viewport: the value until its draws have baked it (bakes.BakeQueue)
            if key in self._queue.empty:  # on no face of this mesh: nothing seen
                return data
            if key in self._queue.failed:
                self._warn(f"Material '{name}': baking its {what} with Cycles failed "
                           f"({self._queue.failed[key]}); using its value")
            else:
                label = f"{name} ({surface.key})"
                self._queue.want(key, lambda: bakes.BakeRequest(
                    _bake_spec(material, mode, socket, surface, auto, self.frame),
                    surface.obj_eval.original.name_full, len(surface.mesh.loops),
                    lambda pixels: _store_bake(key, label, pixels)))
            return data
        if texture is None:
            allowed = self._bake if self._bake is not None else can_bake()
            if not allowed:
                self._warn(f"Material '{name}': its {what} must be baked by Cycles, which "
                           "cannot run here (off the main thread, with no timer of Blender's "
                           "UI to hand it to); using its value until a viewport update or "
                           "voxgi.render_preview bakes it")
                return data
            try:
                pixels = bake_socket(material, mode, socket, surface, auto, self.frame)
            except Exception as error:  # a failed bake must not fail the snapshot
                self._warn(f"Material '{name}': baking its {what} with Cycles failed "
                           f"({error}); using its value")
                return data
            if pixels is None:  # on no face of this mesh: nothing to bake, nothing seen
                return data
            texture = _store_bake(key, f"{name} ({surface.key})", pixels)
        if socket in ("Alpha", CUTOUT_FAC):  # the baked value into the 4th channel
            alpha = _derived(key, "alpha", lambda: TextureData(
                name=texture.name, pixels=np.concatenate(
                    [np.repeat(texture.pixels[..., :1], 3, axis=-1), texture.pixels[..., :1]],
                    axis=-1), interpolation="Linear", extension="EXTEND", key=f"{key}+alpha"))
            return dataclasses.replace(data, alpha_texture=self._add_texture(alpha))
        mean = _derived(key, "mean",
                        lambda: texture.pixels.reshape(-1, 3).mean(axis=0).astype(np.float32))
        if socket == shader_mix.PARAMS:  # Roughness, Metallic per texel; Specular's mean
            def parameters():
                rgb = texture.pixels
                params = np.zeros(rgb.shape[:2] + (4,), np.float32)
                params[..., :2] = np.clip(rgb[..., :2], 0.0, 1.0)
                params[..., 3] = 1.0
                return TextureData(name=f"{texture.name} (roughness, metallic)", pixels=params,
                                   interpolation="Linear", extension="EXTEND", key=f"{key}+params")

            roughness, metallic, specular = (float(c) for c in mean)
            return dataclasses.replace(
                data, roughness=roughness, metallic=metallic, specular=specular,
                param_texture=self._add_texture(_derived(key, "params", parameters)))
        if socket in ("Emission Color", EMISSION_SHADER):  # per texel, × the strength
            return dataclasses.replace(
                data, emission=(mean * np.float32(data.emission_strength)).astype(np.float32),
                emission_texture=self._add_texture(texture))
        return dataclasses.replace(data, base_color=mean,
                                   base_color_texture=self._add_texture(texture))


def _derived(key: str, what: str, make):
    """What a snapshot makes of a baked image (its mean colour, its alpha or parameter texture),
    made once per bake: a full snapshot of the viewport reads every baked material again
    (means over 512² texels took 16 of its 39 ms on the demo box with three bakes)."""
    made = _DERIVED.get((key, what))
    if made is None:
        made = _DERIVED[(key, what)] = make()
    return made


def _reads_images(data: MaterialData) -> bool:
    """Does a material read an image through the mesh's UVs itself (not a bake)?"""
    return max(data.base_color_texture, data.alpha_texture, data.param_texture,
               data.normal_texture, data.emission_texture) >= 0


def _image_channel(socket):
    """(Image Texture node, channel: 0–2 through a Separate Color node (RGB mode), 3 for its
    Alpha output, None for its Color as luminance) feeding a float socket, or None."""
    try:
        node, output = _follow(socket)
        channel = None
        if node is not None and node.type in ("SEPRGB", "SEPARATE_COLOR", "SEPARATE_RGB"):
            if getattr(node, "mode", "RGB") != "RGB":
                return None
            channel = {"R": 0, "G": 1, "B": 2, "Red": 0, "Green": 1, "Blue": 2}.get(
                output.identifier, {"R": 0, "G": 1, "B": 2}.get(output.name))
            if channel is None:
                return None
            node, output = _follow(node.inputs[0])
            if node is None or output.identifier != "Color":
                return None
        elif node is not None and node.type == "TEX_IMAGE" and output.identifier == "Alpha":
            channel = 3
        if node is None or node.type != "TEX_IMAGE" or node.image is None:
            return None
        return node, channel
    except _NeedsBake:
        return None


def _transparent_mix(tree, principled):
    """The Fac socket of the Mix Shader the material output shows when it mixes a Transparent
    BSDF (first shader: Fac = 0 is transparent) with ``principled`` — the cut-out setup
    before the Principled BSDF had an Alpha, whose Fac is the Alpha — else None."""
    output = tree.get_output_node("ALL") if tree is not None else None
    surface = None if output is None else output.inputs.get("Surface")
    if surface is None or not surface.is_linked or principled is None:
        return None
    mix = surface.links[0].from_node
    if mix.type != "MIX_SHADER" or not (mix.inputs[1].is_linked and mix.inputs[2].is_linked):
        return None
    first, second = mix.inputs[1].links[0].from_node, mix.inputs[2].links[0].from_node
    if first.type == "BSDF_TRANSPARENT" and second == principled:
        return mix.inputs[0]
    return None


def _route_cutout_fac(tree) -> None:
    """Make a material copy's ``tree`` render an Emission of its cut-out Mix Shader's Fac
    (``_transparent_mix``: what the Transparent BSDF lets through is 1 − Fac)."""
    output = tree.get_output_node("ALL")
    fac = output.inputs["Surface"].links[0].from_node.inputs[0]
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    if fac.is_linked:
        tree.links.new(fac.links[0].from_socket, emit.inputs["Color"])
    else:
        emit.inputs["Color"].default_value = (*(float(fac.default_value),) * 3, 1.0)
    tree.links.new(emit.outputs[0], output.inputs["Surface"])


def _alpha_node(principled):
    """The Image Texture node whose Alpha output feeds ``principled``'s Alpha, or None."""
    socket = principled.inputs.get("Alpha")
    if socket is not None and not socket.is_linked:
        socket = _transparent_mix(principled.id_data, principled)
    if socket is None or not socket.is_linked:
        return None
    try:
        node, output = _follow(socket)
    except _NeedsBake:
        return None
    if node is None or node.type != "TEX_IMAGE" or output.identifier != "Alpha" or \
            node.image is None or node.image.alpha_mode == "NONE":
        return None
    return node


def _image_texture(node, with_alpha: bool = False):
    """(TextureData of an Image Texture node's image, the UV map it reads) — RGBA with the
    image's alpha channel when ``with_alpha`` — or (None, "") when the image has no pixels;
    raises ``_NeedsBake`` for what only Cycles can evaluate."""
    if node.projection != "FLAT" or node.extension not in ("REPEAT", "EXTEND", "CLIP"):
        raise _NeedsBake(f"the image node '{node.name}' uses {node.projection.lower()} "
                         f"projection / {node.extension.lower()} extension")
    uv_map, transform = uv_source(node)
    rgb, image_key = _cached_image(node.image)
    if rgb is None:
        return None, ""
    tiled = node.image.source == "TILED"
    if with_alpha:  # alpha is linear whatever the colour space
        alpha = udim.atlas(node.image, lambda tile: _image_pixels(tile)[..., 3:4]) if tiled \
            else _image_pixels(node.image)[..., 3:4]
        rgb = np.concatenate([rgb, alpha], axis=-1)
        image_key = f"{image_key}+alpha"
    if tiled:  # UVs to the atlas' cells; beyond its last tiles its edge, not tile 1001 again
        transform = udim.uv_scale(node.image) @ transform
    texture = TextureData(
        name=node.image.name_full, pixels=within_max_size(rgb),
        interpolation="Closest" if node.interpolation == "Closest" else "Linear",
        extension="EXTEND" if tiled else node.extension, uv_transform=transform, key=image_key,
        srgb_bytes=_srgb_bytes(node.image))
    return texture, uv_map


def _uses_node(tree, kind: str, depth: int = 0) -> bool:
    """Does the tree (its groups too) hold a node of type ``kind``?"""
    if tree is None or depth > 8:
        return False
    return any(node.type == kind or (node.type == "GROUP" and _uses_node(node.node_tree, kind,
                                                                         depth + 1))
               for node in tree.nodes)


def _object_info(obj) -> tuple:
    """What Object Info reads of an object besides its place: its Color, Pass Index and Random
    (the bake's object takes them: ``bakes.BakeSpec.object_color``, ``same_random_name``)."""
    return tuple(round(float(c), 6) for c in obj.color), int(obj.pass_index), \
        round(object_random(obj.original.name), 7)


def _uses_object_space(tree, depth: int = 0) -> bool:
    """Does the tree read coordinates that move with the object (Texture Coordinate's Object,
    Camera, Window, Reflection; Geometry)?"""
    if tree is None or depth > 8:
        return False
    for node in tree.nodes:
        if node.type == "NEW_GEOMETRY" or (node.type == "TEX_COORD" and any(
                o.is_linked for o in node.outputs if o.identifier not in ("UV", "Generated"))):
            return True
        if node.type == "GROUP" and _uses_object_space(node.node_tree, depth + 1):
            return True
    return False


MAX_OWN_BAKES = 16  # linked duplicates of one mesh baked each for itself at most (``reads_its_object``)
_OBJECT_INFO_OF_ITS_OWN = ("Color", "Alpha", "Object Index", "Location", "Random")
_POSITION_OUTPUTS = ("Position", "Normal", "Tangent", "True Normal")


def reads_its_object(material) -> bool:
    """Does ``material`` 's Cycles bake depend on which object wears it — Object Info's Color,
    Alpha, Object Index, Location or Random, the Geometry node's world-space outputs, or a
    Texture Coordinate's Object output relative to another object — through nodes the
    per-object variants (``object_base_color``) do not follow? Linked duplicates of its mesh are then
    read and baked each for itself (``snapshot.scene``, at most MAX_OWN_BAKES of them), the
    bake's object given the object's Color, index, place and Random
    (``bakes.same_random_name``)."""
    tree = getattr(material, "node_tree", None)
    return tree is not None and _tree_reads_object(tree, 0) and object_base_color(material) is None


def _tree_reads_object(tree, depth: int) -> bool:
    for node in tree.nodes if tree is not None and depth <= 8 else ():
        if node.type == "OBJECT_INFO" and any(
                o.is_linked for o in node.outputs if o.name in _OBJECT_INFO_OF_ITS_OWN):
            return True
        if node.type == "NEW_GEOMETRY" and any(
                o.is_linked for o in node.outputs if o.name in _POSITION_OUTPUTS):
            return True
        if node.type == "TEX_COORD" and node.object is not None and node.outputs["Object"].is_linked:
            return True
        if node.type == "GROUP" and _tree_reads_object(node.node_tree, depth + 1):
            return True
    return False


def can_bake() -> bool:
    """A Cycles bake is possible here: the main thread, no render job running."""
    if threading.current_thread() is not threading.main_thread():
        return False
    return not (hasattr(bpy.app, "is_job_running") and bpy.app.is_job_running("RENDER"))


def _store_bake(key: str, name: str, pixels: np.ndarray) -> TextureData:
    """A baked socket's image into the bake cache (under its content key), its mean colour
    with it (``_derived``)."""
    texture = _BAKED[key] = TextureData(name=name, pixels=pixels, interpolation="Linear",
                                        extension="EXTEND", key=key)
    _derived(key, "mean", lambda: pixels.reshape(-1, 3).mean(axis=0).astype(np.float32))
    return texture


def _bake_spec(material, mode: str, socket_name: str, surface: Surface,
               auto: bool, frame: int = 1) -> bakes.BakeSpec:
    """What a bake of ``material``'s socket over ``surface`` renders (``bakes.BakeSpec``):
    an Emit bake shows an Emission of the socket (an Emission surface's own,
    EMISSION_SHADER, as it is; a shader mix's parameters; the cut-out Mix's Fac)."""
    layers = surface.mesh.uv_layers
    render_uv = next((layer.name for layer in layers if layer.active_render), None) or \
        (layers.active.name if layers.active is not None else None)

    def route(tree, groups) -> None:
        if socket_name in shader_mix.EXPRESSIONS:
            shader_mix.route_to_emission(tree, socket_name)
        elif socket_name == CUTOUT_FAC:
            _route_cutout_fac(tree)
        elif mode == "EMIT" and socket_name != EMISSION_SHADER:
            route_to_emission(tree, socket_name, groups)

    user = animated.original(material)
    slots = tuple(i for i, m in enumerate(surface.slot_materials)
                  if m is not None and m.original == user)
    return bakes.BakeSpec(
        material=user, mode=mode, route=route, slots=slots,
        last=max(len(surface.slot_materials) - 1, 0), render_uv=render_uv,
        target_uv=AUTO_UVS if auto else render_uv,
        auto_uvs=surface.auto_uvs if auto else None,
        matrix_world=surface.obj_eval.matrix_world.copy(),
        object_color=tuple(surface.obj_eval.color), pass_index=int(surface.obj_eval.pass_index),
        object_name=surface.obj_eval.original.name, frame=int(frame),
        values=tuple(animated.frame_values(material)) if animated.reads_evaluated(material)
        else None)


def bake_socket(material, mode: str, socket_name: str, surface: Surface,
                auto: bool = False, frame: int = 1) -> np.ndarray | None:
    """(BAKE_SIZE, BAKE_SIZE, 3) float32 linear RGB of a material's socket (mode "EMIT": the
    Principled input ``socket_name``) or diffuse colour (mode "DIFFUSE") baked by Cycles over
    the active render UV map of ``surface``'s evaluated mesh (its faces of this material), or
    over its polygons' layout (``auto``); None where no face of the mesh has the material
    (nothing of it is seen: no bake), at the scene's ``frame`` (an image sequence's or a
    movie's). Nothing of the user's data is touched (``bakes.bake_whole``)."""
    return bakes.bake_whole(_bake_spec(material, mode, socket_name, surface, auto, frame),
                            surface.mesh)


classes = ()


def register() -> None:
    if _clear_on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_clear_on_load)


def unregister() -> None:
    clear_bake_cache()
    if _clear_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_clear_on_load)

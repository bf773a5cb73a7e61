"""Any world as an equirect radiance map (``WorldData``), main thread only.

What a camera ray that misses everything sees in Cycles, in the convention of
``voxgi_addon/scene/equirect.py`` (docs/blender_facts.md "World"):

* **uniform**: the Background node's Color x Strength (``World.color`` without a node tree):
  a tiny constant map;
* **image**: an Environment Texture (equirect projection) feeding the Background's Color,
  optionally through a Mapping node fed by Texture Coordinate Generated/Object or nothing: the
  image's pixels are read (``foreach_get``), made linear, box-downsampled to at most 512 rows
  and looked up through the mapping;
* **bake**: anything else (Sky Texture, mixes, ramps, shader mixes, ...): Cycles renders the
  world with a panoramic equirectangular camera into a temporary float EXR — for the live
  viewport in another process (``world_process``), which hands the map back to ``store``.

Maps are cached by the world's content key (``world_key``) in a module-level dict that a
file load clears. A bake needs ``bpy.ops.render.render``: it runs on the main thread only and
not while a render job runs (an F12 in the UI renders on a job thread); there the cache is
used, or the Background's Color x Strength with a warning. In background mode (``bpy``
module, ``blender -b``) F12 calls the engine on the main thread and the nested bake works.
"""
from __future__ import annotations

import hashlib
import math
import os
import shutil
import tempfile
import threading

import bpy
import numpy as np

from ...voxgi_addon.files.exr import read_exr
from ...voxgi_addon.scene import equirect
from ...voxgi_addon.scene.snapshot import WorldData
from ...voxgi_addon.scene.textures import srgb_to_linear
from . import animated

MAX_HEIGHT = 512          # maps are at most 1024 x 512
MIN_HEIGHT = 32           # ... and at least 64 x 32 (a uniform world: UNIFORM_HEIGHT)
UNIFORM_HEIGHT = 8
BAKE_HEIGHT = 256         # a baked world's map: 512 x 256 ...
BAKE_IMAGE_HEIGHT = 512   # ... or 1024 x 512 when it samples an image taller than 256 rows
BAKE_SAMPLES = 16         # box-filtered over each pixel (its mean radiance)
SCENE_LINEAR = ("Linear Rec.709", "scene_linear")
LINEAR_SPACES = ("Linear Rec.709", "scene_linear", "Non-Color")
MAPPING_TYPES = ("POINT", "TEXTURE", "VECTOR", "NORMAL")

AHEAD_WAIT = 120.0  # seconds an F12 that cannot bake waits for the child baking its world
_CACHE: dict[str, tuple[WorldData, tuple[str, ...]]] = {}
_LAST: dict[str, WorldData] = {}  # each world's last baked map, by name (shown while it bakes again)
_BAKES = [0]  # how many bakes ran (tests check that a cached world does not bake again)


class _NeedsBake(Exception):
    """The world must be evaluated by Blender (the message says why)."""


# ---------------------------------------------------------------------------------------------
# cache


def bake_count() -> int:
    """How many Cycles bakes of a world this session ran."""
    return _BAKES[0]


def clear_cache() -> None:
    _CACHE.clear()
    _LAST.clear()


def cached(key: str) -> bool:
    """Whether the map of the world whose content key is ``key`` is in the cache."""
    return key in _CACHE


def store(key: str, radiance: np.ndarray, light_path: bool, name: str = "") -> WorldData:
    """Keep the baked ``radiance`` of the world whose content key is ``key`` (a bake that ran
    elsewhere: ``world_process``), as ``read_world`` keeps its own bakes."""
    data = _map(key, radiance)
    _CACHE[key] = (data, _light_path_notes(name) if light_path else ())
    if name:
        _LAST[name] = data
    return data


def _light_path_notes(name: str) -> tuple[str, ...]:
    return (f"World '{name}' uses a Light Path node: VoxGI lights the scene with what camera "
            "rays see of it",)


@bpy.app.handlers.persistent
def _clear_on_load(*_args) -> None:
    clear_cache()


def _ensure_load_handler() -> None:
    if _clear_on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_clear_on_load)


classes = ()


def register() -> None:
    _ensure_load_handler()


def unregister() -> None:
    clear_cache()
    if _clear_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_clear_on_load)


# ---------------------------------------------------------------------------------------------
# content key

_SKIP = {"rna_type", "location", "location_absolute", "width", "height", "dimensions", "label",
         "parent", "warning_propagation", "use_custom_color", "color", "color_tag", "select",
         "show_options", "show_preview", "hide", "show_texture", "bl_idname", "bl_label",
         "bl_description", "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min",
         "bl_width_max", "bl_height_default", "bl_height_min", "bl_height_max", "inputs",
         "outputs", "internal_links", "name", "image_user", "texture_mapping", "color_mapping",
         "is_active_output", "type"}


def _image_key(image) -> tuple:
    if image is None:
        return ("image", None)
    path = bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""
    mtime = os.path.getmtime(path) if path and os.path.exists(path) else None
    key = ("image", image.name_full, path, mtime, image.source, tuple(image.size), image.is_float,
           image.colorspace_settings.name, image.alpha_mode, image.packed_file is not None)
    packed = image.packed_file
    if image.source == "TILED" and not image.is_dirty:  # its tiles' files or packed bytes
        from .udim import content_key
        key += (content_key(image),)
    elif packed is not None and image.source == "FILE" and not image.is_dirty:
        # its file's bytes, packed: a tenth of its decoded pixels to hash, and no decoding
        key += (hashlib.blake2b(bytes(packed.data), digest_size=16).hexdigest(),)
    elif image.source != "FILE" or image.is_dirty or packed is not None:
        pixels = _image_pixels(image)  # its content is only in memory: hash it
        key += (hashlib.blake2b(pixels.tobytes(), digest_size=16).hexdigest() if pixels is not None else None,)
    return key


def _value_key(value, depth: int):
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, bpy.types.Image):
        return _image_key(value)
    if isinstance(value, bpy.types.Object):
        return ("object", value.name_full, tuple(tuple(row) for row in value.matrix_world))
    if isinstance(value, bpy.types.NodeTree):
        return _tree_key(value, depth + 1)
    if isinstance(value, bpy.types.ID):
        return ("id", value.name_full)
    if isinstance(value, bpy.types.bpy_struct):
        return _struct_key(value, depth + 1) if depth < 4 else None
    if isinstance(value, bpy.types.bpy_prop_collection):
        return tuple(_value_key(item, depth + 1) for item in value) if depth < 4 else None
    try:
        return tuple(_value_key(v, depth) for v in value)
    except TypeError:
        return repr(value)


def _struct_key(struct, depth: int) -> tuple:
    items = []
    for prop in struct.bl_rna.properties:
        name = prop.identifier
        if name in _SKIP:
            continue
        if prop.is_readonly and prop.type not in ("POINTER", "COLLECTION"):
            continue
        items.append((name, _value_key(getattr(struct, name, None), depth)))
    return tuple(items)


def _tree_key(tree, depth: int = 0) -> tuple:
    if depth > 8:
        return ("tree", tree.name_full)
    nodes = []
    for node in sorted(tree.nodes, key=lambda n: n.name):
        inputs = tuple((s.identifier, _value_key(getattr(s, "default_value", None), depth))
                       for s in node.inputs if not s.is_linked)
        nodes.append((node.name, node.bl_idname, node.mute, _struct_key(node, depth), inputs,
                      getattr(node, "is_active_output", None)))
    links = sorted((link.from_node.name, link.from_socket.identifier, link.to_node.name,
                    link.to_socket.identifier, link.is_muted) for link in tree.links)
    return ("tree", tuple(nodes), tuple(links))


def world_objects(world) -> frozenset[str]:
    """Names of the objects whose matrices a world's nodes read (Texture Coordinate's Object,
    in its node groups too): moving one changes the world (``world_key``)."""
    names: set[str] = set()
    _tree_objects(None if world is None else world.node_tree, 0, names)
    return frozenset(names)


def _tree_objects(tree, depth: int, names: set[str]) -> None:
    """Add to ``names`` the objects a node tree's Texture Coordinate nodes read, groups
    followed 8 deep. (A module function: a nested one that calls itself is a reference
    cycle, garbage only the cyclic collector frees, each snapshot.)"""
    for node in tree.nodes if tree is not None and depth < 8 else ():
        if node.type == "TEX_COORD" and node.object is not None:
            names.add(node.object.name_full)
        elif node.type == "GROUP":
            _tree_objects(node.node_tree, depth + 1, names)


def shows_moving_images(tree, depth: int = 0) -> bool:
    """Does the tree (its groups too) read an image sequence or a movie (whose picture
    follows the scene's frame: a bake is then the frame's)?"""
    if tree is None or depth > 8:
        return False
    return any((node.type in ("TEX_IMAGE", "TEX_ENVIRONMENT") and node.image is not None and
                node.image.source in ("SEQUENCE", "MOVIE")) or
               (node.type == "GROUP" and shows_moving_images(node.node_tree, depth + 1))
               for node in tree.nodes)


def world_key(world, frame: int = 1) -> str:
    """A content key of a world: same nodes, values, links, images, mapping objects -> same key
    (and the scene's ``frame`` where it shows an image sequence or a movie)."""
    if world is None:
        return ""
    tree = world.node_tree
    content = (tuple(world.color), tree is not None and _tree_key(tree),
               bpy.data.colorspace.working_space,
               int(frame) if shows_moving_images(tree) else None)
    return hashlib.blake2b(repr(content).encode(), digest_size=16).hexdigest()


# ---------------------------------------------------------------------------------------------
# reading the node tree


def _follow(socket):
    """(node, output socket) feeding an input socket through reroutes, or (None, None)."""
    seen = 0
    while socket.is_linked and seen < 64:
        link = socket.links[0]
        if link.is_muted:
            return None, None
        node = link.from_node
        if node.mute:
            raise _NeedsBake(f"the node '{node.name}' is muted")
        if node.type != "REROUTE":
            return node, link.from_socket
        socket = node.inputs[0]
        seen += 1
    return None, None


def _background_node(tree):
    """The Background node the world output's Surface shows, None for a black world."""
    output = tree.get_output_node("CYCLES")
    if output is None:
        return None
    surface = output.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return None
    node, _ = _follow(surface)
    if node is None:
        return None
    if node.type != "BACKGROUND":
        raise _NeedsBake(f"its surface is a '{node.name}' node")
    return node


def _euler_matrix(rotation) -> np.ndarray:
    """Blender's XYZ Euler rotation matrix (Rz @ Ry @ Rx)."""
    x, y, z = (float(a) for a in rotation)
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _mapping_transform(node):
    """A function of (N, 3) vectors: the Mapping node as Cycles evaluates it."""
    for name in ("Location", "Rotation", "Scale"):
        socket = node.inputs.get(name)
        if socket is not None and socket.is_linked:
            raise _NeedsBake(f"the Mapping node '{node.name}' has a linked {name}")
    kind = node.vector_type
    rotation = _euler_matrix(node.inputs["Rotation"].default_value)
    scale = np.array(node.inputs["Scale"].default_value, np.float64)
    location = np.array(node.inputs["Location"].default_value, np.float64) if kind in ("POINT", "TEXTURE") else 0.0

    def safe_divide(a, b):
        return np.divide(a, b, out=np.zeros_like(a), where=b != 0)

    def transform(v):
        if kind == "POINT":
            return (v * scale) @ rotation.T + location
        if kind == "TEXTURE":
            return safe_divide((v - location) @ rotation, scale)
        if kind == "VECTOR":
            return (v * scale) @ rotation.T
        out = safe_divide(v, scale) @ rotation.T  # NORMAL
        length = np.linalg.norm(out, axis=-1, keepdims=True)
        return np.divide(out, length, out=np.zeros_like(out), where=length > 0)

    return transform


def _texture_vector(env):
    """A function (N, 3) view directions -> (N, 3) texture vectors of the Environment Texture."""
    socket = env.inputs.get("Vector")
    if socket is None or not socket.is_linked:
        return None
    node, output = _follow(socket)
    transforms = []
    if node is not None and node.type == "MAPPING":
        if node.vector_type not in MAPPING_TYPES:
            raise _NeedsBake(f"the Mapping node '{node.name}' is of type {node.vector_type}")
        transforms.append(_mapping_transform(node))
        vector = node.inputs.get("Vector")
        if vector is None or not vector.is_linked:
            raise _NeedsBake(f"the Mapping node '{node.name}' has no vector input")
        node, output = _follow(vector)
    if node is None or node.type != "TEX_COORD" or output.identifier not in ("Generated", "Object"):
        name = "nothing" if node is None else f"'{node.name}'" + (f" ({output.name})" if output else "")
        raise _NeedsBake(f"the Environment Texture's vector comes from {name}")
    if output.identifier == "Object" and node.object is not None:
        inverse = np.linalg.inv(np.array(node.object.matrix_world, np.float64))
        transforms.append(lambda v: v @ inverse[:3, :3].T + inverse[:3, 3])
    transforms.reverse()

    def apply(v):
        for transform in transforms:
            v = transform(v)
        return v

    return apply


def _image_pixels(image) -> np.ndarray | None:
    """(H, W, 4) float32 of an image as ``image.pixels`` holds it (row 0 = bottom), or None."""
    width, height = image.size
    if width == 0 or height == 0:
        return None
    flat = np.empty(width * height * image.channels, np.float32)
    image.pixels.foreach_get(flat)
    pixels = flat.reshape(height, width, image.channels)
    if image.channels == 4:
        return pixels
    out = np.ones((height, width, 4), np.float32)
    out[..., :min(3, image.channels)] = pixels[..., :3]
    if image.channels < 3:
        out[..., 1:3] = pixels[..., :1]
    return out


def _image_radiance(image) -> np.ndarray:
    """An image's linear RGB in our convention at its own size (rows top-down, columns
    mirrored: Cycles' equirect u runs against our azimuth), box-downsampled to MAX_HEIGHT."""
    if image.source not in ("FILE", "GENERATED"):
        raise _NeedsBake(f"the image '{image.name}' is a {image.source.lower()}")
    space = image.colorspace_settings.name
    if bpy.data.colorspace.working_space not in SCENE_LINEAR:
        raise _NeedsBake(f"the file's working colour space is {bpy.data.colorspace.working_space}")
    pixels = _image_pixels(image)
    if pixels is None:
        raise _NeedsBake(f"the image '{image.name}' has no pixels (missing file?)")
    if np.any(pixels[..., 3] < 1.0) and image.alpha_mode != "CHANNEL_PACKED":
        raise _NeedsBake(f"the image '{image.name}' has transparent pixels")
    rgb = pixels[..., :3]
    if space not in LINEAR_SPACES:
        if image.is_float or space != "sRGB":
            raise _NeedsBake(f"the image '{image.name}' is in the colour space '{space}'")
        rgb = srgb_to_linear(rgb)  # byte pixels hold the encoded values (docs "World")
    return equirect.box_downsample(rgb[::-1, ::-1], MAX_HEIGHT)


def needs_bake(world) -> bool:
    """Whether Cycles must evaluate ``world`` (``read_world``'s bake), found without reading
    any image."""
    try:
        _read_nodes(world, "", probe=True)
    except _NeedsBake:
        return True
    return False


def _read_nodes(world, key: str, probe: bool = False) -> WorldData:
    """Uniform or image world read from its nodes; raises _NeedsBake for anything else.
    probe : stop before reading an image (``needs_bake``)."""
    tree = world.node_tree
    if tree is None:
        return _uniform(key, np.array(world.color[:3], np.float32), 1.0)
    background = _background_node(tree)
    if background is None:
        return WorldData(key=key)
    strength_socket = background.inputs["Strength"]
    if strength_socket.is_linked:
        raise _NeedsBake("the Background's Strength is linked")
    strength = float(strength_socket.default_value)
    color = background.inputs["Color"]
    if not color.is_linked:
        return _uniform(key, np.array(color.default_value[:3], np.float32), strength)
    node, output = _follow(color)
    if node is None:
        return _uniform(key, np.array(color.default_value[:3], np.float32), strength)
    if node.type != "TEX_ENVIRONMENT" or output.identifier != "Color":
        raise _NeedsBake(f"the Background's Color comes from '{node.name}'")
    if node.projection != "EQUIRECTANGULAR":
        raise _NeedsBake(f"the Environment Texture '{node.name}' uses {node.projection} projection")
    if node.image is None:
        raise _NeedsBake(f"the Environment Texture '{node.name}' has no image")
    if strength == 0.0:
        return WorldData(color=np.zeros(3, np.float32), strength=0.0, key=key)
    transform = _texture_vector(node)
    if probe:
        return WorldData(key=key)
    source = _image_radiance(node.image)
    height, width = source.shape[:2]
    if transform is None and width == 2 * height and height >= MIN_HEIGHT:
        radiance = source
    else:
        height = int(np.clip(height, MIN_HEIGHT, MAX_HEIGHT))
        directions = equirect.pixel_directions(height, 2 * height).reshape(-1, 3)
        vectors = transform(directions) if transform is not None else directions
        radiance = equirect.sample_bilinear(source, vectors).reshape(height, 2 * height, 3)
    return _map(key, radiance * np.float32(strength))


def _uniform(key: str, color: np.ndarray, strength: float) -> WorldData:
    value = color * np.float32(strength)
    radiance = None
    if np.any(value != 0):
        radiance = np.broadcast_to(value, (UNIFORM_HEIGHT, 2 * UNIFORM_HEIGHT, 3)).astype(np.float32)
    return WorldData(color=color.astype(np.float32), strength=float(strength), radiance=radiance,
                     key=key)


def _map(key: str, radiance: np.ndarray) -> WorldData:
    radiance = np.ascontiguousarray(radiance, np.float32)
    if not np.any(radiance != 0):
        return WorldData(key=key)
    radiance.setflags(write=False)
    return WorldData(color=equirect.mean_radiance(radiance), strength=1.0, radiance=radiance, key=key)


# ---------------------------------------------------------------------------------------------
# baking with Cycles


def _uses_images_taller_than(tree, rows: int, depth: int = 0) -> bool:
    for node in tree.nodes:
        image = getattr(node, "image", None)
        if image is not None and image.size[1] > rows:
            return True
        group = getattr(node, "node_tree", None)
        if group is not None and depth < 8 and _uses_images_taller_than(group, rows, depth + 1):
            return True
    return False


def bake_height(tree) -> int:
    """The rows of a baked map of a world whose nodes are ``tree``."""
    return BAKE_IMAGE_HEIGHT if _uses_images_taller_than(tree, BAKE_HEIGHT) else BAKE_HEIGHT


def uses_light_path(tree, depth: int = 0) -> bool:
    for node in tree.nodes:
        if node.type == "LIGHT_PATH":
            return True
        group = getattr(node, "node_tree", None)
        if group is not None and depth < 8 and uses_light_path(group, depth + 1):
            return True
    return False


def can_bake() -> bool:
    """A nested Cycles render is possible here: the main thread, no render job running."""
    if threading.current_thread() is not threading.main_thread():
        return False
    return not (hasattr(bpy.app, "is_job_running") and bpy.app.is_job_running("RENDER"))


def bake_world(world, height: int = BAKE_HEIGHT, samples: int = BAKE_SAMPLES,
               frame: int = 1) -> np.ndarray:
    """(height, 2 height, 3) float32 radiance of ``world`` rendered by Cycles (main thread),
    at the scene's ``frame`` (an image sequence's or a movie's picture).

    A temporary scene holds only a panoramic equirectangular camera (rotated so that the
    render, mirrored left-right, is in our convention: docs/blender_facts.md "World") and the
    world; each pixel is the mean over its area (box filter of one pixel, ``samples``
    samples), no denoising, written to a temporary float EXR and read back. Everything
    temporary is removed afterwards, also when the render fails.
    """
    tmp = tempfile.mkdtemp(prefix="voxgi-world-")
    path = os.path.join(tmp, "world.exr")
    camera = bpy.data.cameras.new("VoxGI World Bake")
    obj = scene = copy = None
    groups: list = []
    try:
        # a copy of the world without its light's importance map (Cycles builds one for
        # lighting objects: none here; it cost 0.7 of a 0.75 s bake of a Gradient sky)
        # (of the user's world: a copy of the depsgraph's would point at its node groups and
        # objects; an animated world's values at the depsgraph's frame go to the copy)
        copy = animated.original(world).copy()
        if animated.reads_evaluated(world):
            groups = animated.apply(copy, animated.frame_values(world))
        if hasattr(copy, "cycles"):
            copy.cycles.sampling_method = "NONE"
        camera.type = "PANO"
        camera.panorama_type = "EQUIRECTANGULAR"
        camera.latitude_min, camera.latitude_max = -math.pi / 2, math.pi / 2
        camera.longitude_min, camera.longitude_max = -math.pi, math.pi
        obj = bpy.data.objects.new("VoxGI World Bake", camera)
        obj.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
        scene = bpy.data.scenes.new("VoxGI World Bake")
        scene.frame_current = int(frame)
        scene.collection.objects.link(obj)
        scene.camera = obj
        scene.world = copy
        render = scene.render
        render.engine = "CYCLES"
        render.resolution_x, render.resolution_y, render.resolution_percentage = 2 * height, height, 100
        render.pixel_aspect_x = render.pixel_aspect_y = 1.0
        render.film_transparent = False
        render.use_compositing = render.use_sequencer = False
        render.filepath, render.use_file_extension = path, False
        settings = render.image_settings
        settings.media_type = "MULTI_LAYER_IMAGE"
        settings.file_format = "OPEN_EXR_MULTILAYER"
        settings.color_depth = "32"
        settings.exr_codec = "ZIP"
        cycles = scene.cycles
        cycles.device = "CPU"
        cycles.samples = int(samples)
        cycles.use_adaptive_sampling = False
        cycles.use_denoising = False
        cycles.pixel_filter_type = "BOX"
        cycles.filter_width = 1.0
        cycles.seed = 0
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
        _BAKES[0] += 1
        bpy.ops.render.render(write_still=True, scene=scene.name)
        if not os.path.exists(path):
            raise RuntimeError("Cycles wrote no image")
        channels = read_exr(path)
        layer = next(name[:-len("Combined.R")] for name in channels if name.endswith("Combined.R"))
        image = np.stack([channels[f"{layer}Combined.{c}"] for c in "RGB"], axis=-1)
        return np.ascontiguousarray(image[:, ::-1], np.float32)
    finally:
        if scene is not None:
            bpy.data.scenes.remove(scene)
        if obj is not None:
            bpy.data.objects.remove(obj)
        if copy is not None:
            bpy.data.worlds.remove(copy)
        for group in groups:  # (an animated node group's copy, ``animated.apply``)
            bpy.data.node_groups.remove(group)
        bpy.data.cameras.remove(camera)
        shutil.rmtree(tmp, ignore_errors=True)


def _fallback(world, key: str) -> WorldData:
    """The Background's Color x Strength (World.color without nodes) when a bake cannot run."""
    tree = world.node_tree
    background = None
    if tree is not None:
        background = next((n for n in tree.nodes if n.type == "BACKGROUND"), None)
    if background is None:
        return _uniform(key, np.array(world.color[:3], np.float32), 1.0)
    color = background.inputs["Color"].default_value
    strength = background.inputs["Strength"].default_value
    return _uniform(key, np.array(color[:3], np.float32), float(strength))


# ---------------------------------------------------------------------------------------------
# entry


def read_world(world, warnings: list[str], bake: bool | None = None, deferred=None,
               frame: int = 1) -> WorldData:
    """``WorldData`` of a world (None: a black world), read directly where its nodes allow and
    baked by Cycles otherwise. ``bake``: allow a bake (None: where ``can_bake()``).
    ``deferred``: the live viewport's ``world_process.WorldBakes``, which bakes the world in
    another process where it can (``world_process.deferrable``); the world's last map, or its
    Background's Color x Strength, stands in meanwhile. What cannot be read is said in
    ``warnings`` (once per call). ``frame``: the scene's (an image sequence's or a movie's
    picture)."""
    if world is None:
        return WorldData()
    _ensure_load_handler()
    key = world_key(world, frame)
    cached = _CACHE.get(key)
    if cached is not None:
        warnings.extend(cached[1])
        return cached[0]
    notes: list[str] = []
    try:
        data = _read_nodes(world, key)
    except _NeedsBake as reason:
        tree = world.node_tree
        height = bake_height(tree)
        if deferred is not None and key not in deferred.failed:
            from .world_process import deferrable

            if deferrable(world):
                try:
                    deferred.want(world, key, height, uses_light_path(tree), frame=frame)
                except Exception as error:  # noqa: BLE001 - baked here instead
                    deferred.failed[key] = str(error) or type(error).__name__
                else:
                    return _LAST.get(world.name_full) or _fallback(world, key + ":pending")
        if bake is None:
            bake = can_bake()
        if not bake:
            from .bakes import render_bakes
            from .world_process import ahead, deferrable

            if key not in ahead.running and key not in ahead.failed and \
                    render_bakes.available() and deferrable(world):
                # F12 in the UI at a frame whose world no child baked ahead (a keyframed
                # sky): the main thread's timer starts one for it
                render_bakes.start_world(world, key, height, uses_light_path(tree), frame)
            ahead.wait(key, AHEAD_WAIT, store)  # baked for this F12 by a child: its map
            cached = _CACHE.get(key)  # (also when the timer collected it first)
            if cached is not None:
                warnings.extend(cached[1])
                return cached[0]
            if key in ahead.failed:
                reason = f"{reason} (its bake in another process failed: {ahead.failed[key]})"
            warnings.append(
                f"World '{world.name}': {reason}, so Cycles must evaluate it, which cannot run "
                "here (off the main thread, and no child baked it ahead); using the "
                "Background's Color x Strength until the world is evaluated (any viewport "
                "update or voxgi.render_preview does it)")
            return _fallback(world, key + ":fallback")
        try:
            data = _map(key, bake_world(world, height, frame=frame))
        except Exception as error:  # a failed bake must not fail the snapshot
            warnings.append(f"World '{world.name}': evaluating it with Cycles failed ({error}); "
                            "using the Background's Color x Strength")
            return _fallback(world, key + ":fallback")
        _LAST[world.name_full] = data
        if uses_light_path(tree):
            notes.extend(_light_path_notes(world.name))
    _CACHE[key] = (data, tuple(notes))
    warnings.extend(notes)
    return data

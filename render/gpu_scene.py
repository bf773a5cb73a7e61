"""One GPU-side scene per snapshot: what the Accurate kernels read, uploaded once and then
updated by what changed (docs/gi_pipeline.md "One GPU scene per snapshot").

A ``GPUScene`` holds, for the latest snapshot it was updated with:

* ``tris`` — the world-space triangles (``scene.geometry.world_triangles``) and ``bvh``, their
  BVH textures (``gpu_bvh.GPUBVH``, the session's ``shared_bvh``);
* ``materials`` — the Principled materials texture (``gpu_gather.principled_materials_texture``)
  with the numpy tables it was made of (``rough``, ``emission``, ``principled``), and
  ``lut``, the Principled LUT (``gpu_principled.lut_texture``);
* ``lights`` — the lights list (``world_light.scene_lights``: lamps, world, emitters) and its
  tables: ``lamp_table`` (every lamp, the gathers'), ``lamp_tables`` (one per lamp, the other
  rows padding: the direct light's per-lamp dispatches), ``no_lamp`` (padding only: the world's
  and emitters' dispatch), ``world_map`` and ``emitters`` (``gpu_bvh.world_texture`` /
  ``emitters_texture``, each with its stream), and ``no_world`` / ``no_emitters`` (their "none"
  tables: what a lamp's own dispatch reads).

``update(snapshot)`` keys each part by its content — the snapshot carries no version counters,
so geometry is a digest of the objects' matrices, the meshes' arrays and the armatures' poses
(one per ``MeshData`` object, reused while the snapshotter hands the same object again), the
materials and lamps the bytes of their tables, the world its ``WorldData.key`` — and rebuilds
and uploads only the parts whose key changed; a part whose new table has the bytes of the
uploaded one (the emitters after a non-emissive object moved) is not uploaded again.
``uploaded`` says what the last update (and the render after it) sent: part → bytes.

Textures and compute shaders are shared between GPU contexts (docs/blender_facts.md, and
docs/gi_pipeline.md "One file's state"), so one scene serves F12, ``voxgi.render_preview``, the
viewport and probe bakes (``current_scene``). It holds no raster shader. A file load drops it
(a ``load_post`` handler), as the sessions are dropped; ``release`` frees it on unregister and
at exit. Needs a GPU context; main thread only.
"""
from __future__ import annotations

import hashlib
import time

import bpy
import gpu
import numpy as np

from ..voxgi_addon.gi.emitters import emitter_table
from ..voxgi_addon.gi.world_light import scene_lights, world_table
from ..voxgi_addon.preview.light_table import LIGHT_TEXELS, light_table
from ..voxgi_addon.preview.passes import material_table, principled_table
from ..voxgi_addon.scene.bvh import TEXTURE_WIDTH
from ..voxgi_addon.scene.geometry import world_triangles
from ..voxgi_addon.scene.glass import ray_alpha
from ..voxgi_addon.scene.textures import pack_atlas
from .gpu_bvh import GPUBVH, absent_lights, shared_bvh
from .gpu_gather import no_texture_inputs, principled_materials_texture
from .gpu_principled import lut_texture
from .gpu_volume import float_texture

# What ``uploaded`` names: the parts of a scene.
PARTS = ("bvh", "materials", "textures", "constants", "lights", "world", "emitters")


def _feed(h, value) -> None:
    """Add ``value`` (array, None, scalar, string or a tuple of these) to the hash ``h``."""
    if value is None:
        h.update(b"\x00none")
    elif isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        h.update(f"{array.dtype.str}{array.shape}".encode())
        h.update(array.view(np.uint8).reshape(-1) if array.size else b"")
    elif isinstance(value, (tuple, list)):
        h.update(f"({len(value)}".encode())
        for item in value:
            _feed(h, item)
        h.update(b")")
    else:
        h.update(repr(value).encode())
        h.update(b"\x00")


def digest(*values) -> str:
    """A content key of ``values`` (numpy arrays by dtype, shape and bytes)."""
    h = hashlib.blake2b(digest_size=16)
    _feed(h, values)
    return h.hexdigest()


def _optional(array):
    return None if array is None else np.asarray(array)


def _mesh_digest(mesh) -> str:
    skin = mesh.skin
    return digest(np.asarray(mesh.positions), np.asarray(mesh.triangles),
                  np.asarray(mesh.triangle_materials), _optional(mesh.corner_normals),
                  _optional(mesh.uvs),
                  None if skin is None else (np.asarray(skin.weights),
                                             np.asarray(skin.bone_indices), skin.armature))


def _texture_key(texture):
    """A snapshot texture's content (``TextureData``: pixels by their key, sampling)."""
    pixels = getattr(texture, "pixels", None)
    return (getattr(texture, "key", "") or (None if pixels is None else digest(pixels)),
            getattr(texture, "interpolation", None), getattr(texture, "extension", None),
            _optional(getattr(texture, "uv_transform", None)))


def _texture_bytes(table: np.ndarray) -> int:
    return int(np.asarray(table, np.float32).nbytes)


def _table_texture(table: np.ndarray):
    """An RGBA32F texture of a (rows, texels, 4) table (texels wide)."""
    return float_texture(table, (table.shape[1], table.shape[0]))


def lamp_tables(lights) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """(every lamp's table, one table per lamp index, the no-lamp table) of
    ``gpu_bvh.lights_texture(lights, only)`` for only None, 0 … len − 1 and −1, from one
    ``light_table``: the rows of the other lamps become padding (type −1), so each lamp's
    samples keep their stream; a table with no row gets one padding row."""
    table = light_table(lights)

    def only(index):
        kept = table.copy()
        if index is not None:
            kept[kept[:, 0, 3] != index, 0, 0] = -1.0
        if len(kept) == 0:
            kept = np.zeros((1, LIGHT_TEXELS, 4), np.float32)
            kept[0, 0, 0] = -1.0
        return np.asarray(kept, np.float32)

    return only(None), [only(i) for i in range(len(lights))], only(-1)


class GPUScene:
    """The GPU-side scene of the latest snapshot (see the module doc).

    uploaded : part (``PARTS``) → bytes sent by the last ``update``; empty when nothing
    was. keys : part → the content key of what is
    uploaded. seconds : part → time of its last rebuild + upload. bvh : a ``GPUBVH`` of its
    own (tests: a scene sharing nothing), else the session's ``shared_bvh``."""

    def __init__(self, bvh: GPUBVH | None = None):
        self._own_bvh = bvh
        self.bvh = bvh or shared_bvh()
        self.tris = None
        self.rough = self.emission = self.principled = None
        self.materials = self.lut = self.no_world = self.no_emitters = None
        self.lights: list = []
        self._tail: list = []  # the lights list's world and emitters
        self.textures: dict[str, object] = {}  # texture_table, texture_atlas
        self.slots = None
        self.lamp_table = self.no_lamp = self.world_map = self.emitters = None
        self.lamp_tables: list = []
        self.keys: dict[str, object] = {}
        self.uploaded: dict[str, int] = {}
        self.seconds: dict[str, float] = {}
        self._meshes: dict[int, tuple[object, str]] = {}  # id(MeshData) → (it, its digest)

    @property
    def uploaded_bytes(self) -> int:
        return sum(self.uploaded.values())

    def _sent(self, part: str, nbytes: int) -> None:
        self.uploaded[part] = self.uploaded.get(part, 0) + int(nbytes)

    # ------------------------------------------------------------------ keys

    def geometry_key(self, snapshot) -> str:
        """Content key of what ``world_triangles`` makes of ``snapshot``: the objects (mesh,
        kind, armature, matrix), their meshes' arrays (UVs included) and the armatures, and
        the materials' per-texel textures (``SceneTriangles.textures``, where the snapshot
        has them). Whatever ``world_triangles`` reads must be in here."""
        meshes = {}
        for obj in snapshot.objects:
            mesh = snapshot.meshes.get(obj.mesh)
            if mesh is None or id(mesh) in meshes:
                continue
            known = self._meshes.get(id(mesh))
            meshes[id(mesh)] = known if known is not None and known[0] is mesh else \
                (mesh, _mesh_digest(mesh))
        self._meshes = meshes  # only this snapshot's meshes stay referenced
        objects = tuple(
            (o.name, o.mesh, o.kind, o.armature, np.asarray(o.world_matrix, np.float64),
             getattr(o, "visibility", None), getattr(o, "holdout", None),
             meshes[id(snapshot.meshes[o.mesh])][1] if o.mesh in snapshot.meshes else None)
            for o in snapshot.objects)
        armatures = tuple(
            (name, a.bone_names, np.asarray(a.parents), np.asarray(a.rest_matrices),
             np.asarray(a.pose_matrices), np.asarray(a.world_matrix))
            for name, a in sorted(snapshot.armatures.items()))
        textures = (tuple((getattr(m, "base_color_texture", -1), getattr(m, "alpha_texture", -1),
                           float(getattr(m, "alpha", 1.0)),
                           ray_alpha(m, getattr(snapshot, "refractive_caustics", True)))
                          for m in snapshot.materials),
                    tuple(_texture_key(t) for t in getattr(snapshot, "textures", ())))
        return digest(objects, armatures, textures, tuple(getattr(snapshot, "holdout_materials", ())))

    # ------------------------------------------------------------------ update

    def update(self, snapshot) -> GPUScene:
        """Make the scene ``snapshot``'s: rebuild and upload the parts whose content changed
        (``uploaded`` says which). The triangles may be empty (nothing is then built for them;
        the caller decides what an empty scene means)."""
        self.uploaded = {}
        self.bvh = self._own_bvh or shared_bvh()  # gpu_bvh.release may have made a new one
        t0 = time.perf_counter()
        geometry = self.geometry_key(snapshot)
        geometry_changed = geometry != self.keys.get("geometry") or self.tris is None
        if geometry_changed:
            self.tris = world_triangles(snapshot)
            self.keys["geometry"] = geometry
        if len(self.tris):
            # identity check first (free); another user of the shared BVH (the Fast path) may
            # have uploaded other triangles since, which a content comparison then catches
            self.bvh.update(self.tris)
            self.bvh.surface = {}
            if self.bvh.uploaded_bytes:
                self._sent("bvh", self.bvh.uploaded_bytes)
                self.seconds["bvh"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        _, rough, _, emission = material_table(snapshot)
        principled = principled_table(snapshot)
        self._update_textures(geometry)
        if getattr(self.tris.textures, "cutout", None) is not None:
            self.bvh.surface = dict(self.textures)  # cut-outs read their Alpha there
        t0 = time.perf_counter()
        surface = getattr(self.tris, "textures", None)
        variants = (None, None) if surface is None else (surface.param_slots, surface.variants)
        glow = (None, None) if surface is None else \
            (surface.emission_slots, surface.emission_strength)
        materials = digest(rough, emission, *principled, self.slots, *variants, *glow)
        materials_changed = materials != self.keys.get("materials")
        if materials_changed:
            self.rough, self.emission, self.principled = rough, emission, principled
            self.materials = principled_materials_texture(principled, emission, self.slots,
                                                          variants, glow)
            self._sent("materials", 5 * len(principled[0]) * 16)
            self.keys["materials"] = materials
            self.seconds["materials"] = time.perf_counter() - t0
        lut = lut_texture()  # constant; cached by gpu_principled
        if lut is not self.lut:
            self.lut = lut
            self._sent("constants", lut.width * lut.height * 16)
        if self.no_world is None:
            none = (world_table(None, 0), emitter_table(None, 0))
            self.no_world, self.no_emitters = (_table_texture(table) for table in none)
            self._sent("constants", sum(_texture_bytes(table) for table in none))

        t0 = time.perf_counter()
        lamps = list(snapshot.lights)
        every, each, none = lamp_tables(lamps)
        lamp_key = digest(len(lamps), every)
        if lamp_key != self.keys.get("lights"):
            self.lamp_table = _table_texture(every)
            self.lamp_tables = [_table_texture(table) for table in each]
            self.no_lamp = _table_texture(none)
            self._sent("lights", sum(_texture_bytes(t) for t in (every, *each, none)))
            self.keys["lights"] = lamp_key
            self.seconds["lights"] = time.perf_counter() - t0

        # the world and the emitters follow the lamps in the lights list; their streams are
        # their indices there
        t0 = time.perf_counter()
        world = snapshot.world
        world_key = None if world.radiance is None else (world.key or digest(world.radiance))
        tail_key = (geometry, materials, world_key)
        if tail_key != self.keys.get("tail"):
            self._tail = scene_lights(snapshot, self.tris, emission)[len(lamps):]
            self.keys["tail"] = tail_key
        self.lights = lamps + self._tail
        found = {light.type: (light, index) for index, light in enumerate(self.lights)
                 if light.type in ("WORLD", "EMITTERS")}
        world_light, stream = found.get("WORLD", (None, 0))
        key = (world_key, stream)
        if key != self.keys.get("world"):
            table = world_table(world_light, stream)
            self.world_map = _table_texture(table)
            self._sent("world", _texture_bytes(table))
            self.keys["world"] = key
            self.seconds["world"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        emitters, stream = found.get("EMITTERS", (None, 0))
        key = (geometry, materials, stream)
        if key != self.keys.get("emitters_source"):
            table = emitter_table(emitters, stream)
            content = digest(table)
            if content != self.keys.get("emitters"):  # e.g. a non-emissive object moved
                self.emitters = _table_texture(table)
                self._sent("emitters", _texture_bytes(table))
                self.keys["emitters"] = content
                self.seconds["emitters"] = time.perf_counter() - t0
            self.keys["emitters_source"] = key
        return self

    def _update_textures(self, geometry: str) -> None:
        """The ``textures`` part, two textures (the gathers' kernels have one sampler to spare
        per stage, not three): ``texture_atlas``, every level of every texture
        (``scene.textures.pack_atlas``; RGBA16F, as the numpy pyramids hold half floats), and
        ``texture_table``, RGBA32F BVH_WIDTH wide: row s = texture s's table row, then from
        the row its texel (BVH_WIDTH − 1, 0) names, the triangles' corner UVs (2 texels per
        triangle index: (uv0, uv1), (uv2, alpha texture or -1, alpha value): ``textures.glsl``
        ``bvh_cutout_counts``). Keyed by the textures' content and the geometry (which holds
        the materials' texture indices and alphas); 1 × 1 stand-ins without textures."""
        t0 = time.perf_counter()
        surface = getattr(self.tris, "textures", None) if self.tris is not None else None
        if surface is None:
            if self.keys.get("textures") != "none":
                self.textures, self.slots = no_texture_inputs(), None
                self.keys["textures"] = "none"
                self.keys.pop("texture_table", None)
            return
        self.slots = surface.slots
        key = digest(tuple((t.key or digest(t.pixels), t.interpolation, t.extension,
                            np.asarray(t.uv_transform, np.float64)) for t in surface.textures))
        atlas = table = None
        if key != self.keys.get("textures"):
            atlas, table = pack_atlas(surface.textures)
            self.textures = {**self.textures, "texture_atlas": float_texture(
                atlas, (atlas.shape[1], atlas.shape[0]), "RGBA16F")}
            self._sent("textures", atlas.size * 2)
            self.keys["textures"] = key
        if (key, geometry) != self.keys.get("texture_table"):
            if table is None:
                table = pack_atlas(surface.textures)[1]
            uvs = np.asarray(surface.uvs, np.float32).reshape(-1, 6)
            texels = np.zeros((len(uvs), 2, 4), np.float32)
            texels[:, 0], texels[:, 1, :2] = uvs[:, :4], uvs[:, 4:]
            if surface.alpha_slots is not None:
                row = surface.row_of(self.tris.materials)
                texels[:, 1, 2] = surface.alpha_slots[row]
                texels[:, 1, 3] = surface.alpha_values[row]
            flat = texels.reshape(-1, 4)
            head = len(table)
            rows = head + max(1, -(-len(flat) // TEXTURE_WIDTH))
            out = np.zeros((rows * TEXTURE_WIDTH, 4), np.float32)
            grid = out.reshape(rows, TEXTURE_WIDTH, 4)
            grid[:head, :table.shape[1]] = table
            grid[0, TEXTURE_WIDTH - 1, 0] = head
            out[head * TEXTURE_WIDTH:head * TEXTURE_WIDTH + len(flat)] = flat
            self.textures = {**self.textures,
                             "texture_table": float_texture(out, (TEXTURE_WIDTH, rows))}
            self._sent("textures", out.nbytes)
            self.keys["texture_table"] = (key, geometry)
        self.seconds["textures"] = time.perf_counter() - t0

    @property
    def textured(self) -> bool:
        """Some material samples a texture (the G-buffer samples it, ``raster_textures``)."""
        return self.slots is not None

    def raster_textures(self):
        """(texture table, atlas) for ``gbuffer.rasterize``, None without textures."""
        return (self.textures["texture_table"], self.textures["texture_atlas"]) \
            if self.textured else None

    # ------------------------------------------------------------------ what kernels read

    @property
    def has_scene_lights(self) -> bool:
        """True when the world or emitters shed light (their own dispatch and gathers)."""
        return len(self.lights) > len(self.lamp_tables)

    def inputs(self) -> dict[str, object]:
        """Every scene sampler of the BVH kernels (``gpu_bvh.KERNELS``: BVH nodes, triangles
        and normals, the lamps', world's and emitters' tables, materials, LUT) by name; add
        the G-buffer's (or a probe's ray origins) to dispatch ``bvh_gather``/``bvh_glossy``."""
        return {**self.bvh.inputs, **self.gather_tables()}

    def gather_tables(self) -> dict[str, object]:
        """The light and material textures of the gathers (``gpu_gather.gather``'s
        ``tables``), and what picks the kernels' variant (``gpu_bvh.bvh_shader``):
        "bvh_textures", whether their hits sample textures, and "bvh_absent", the kinds of
        light the scene has none of."""
        return {"lights": self.lamp_table, "world_map": self.world_map,
                "emitters": self.emitters, "materials": self.materials,
                "principled_lut": self.lut, **self.textures, "bvh_textures": self.textured,
                "bvh_absent": absent_lights(self.lights)}

    @staticmethod
    def zeros(width: int, height: int):
        """A new width × height RGBA32F texture of zeros, cleared on the GPU: nothing is
        uploaded, and nothing of a render's size is kept between renders."""
        texture = gpu.types.GPUTexture((int(width), int(height)), format="RGBA32F")
        texture.clear(format="FLOAT", value=(0.0, 0.0, 0.0, 0.0))
        return texture


_current: GPUScene | None = None


def peek_scene() -> GPUScene | None:
    """The current scene if there is one (tests, reports), without making one."""
    return _current


def current_scene(snapshot=None) -> GPUScene:
    """The session's ``GPUScene`` (one for F12, the operators, the viewport and probe bakes),
    updated to ``snapshot`` when one is given. Dropped on file load and by ``release``."""
    global _current
    if _current is None:
        _current = GPUScene()
        if _drop_on_load not in bpy.app.handlers.load_post:
            bpy.app.handlers.load_post.append(_drop_on_load)
    if snapshot is not None:
        _current.update(snapshot)
    return _current


@bpy.app.handlers.persistent
def _drop_on_load(*_args) -> None:
    # What was uploaded belongs to the file it came from (docs/gi_pipeline.md "One file's
    # state"): the next render builds the new file's scene.
    global _current
    _current = None


def release() -> None:
    """Drop the current scene's textures and the load handler (unregister, exit)."""
    global _current
    _current = None
    if _drop_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_drop_on_load)

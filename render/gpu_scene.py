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

import dataclasses
import hashlib
import threading
import time

import bpy
import gpu
import numpy as np

from ..voxgi_addon.gi.emitters import emitter_table
from ..voxgi_addon.gi.world_light import scene_lights, sun_lamp, sun_shadow, world_light, world_table
from ..voxgi_addon.preview.light_table import LIGHT_TEXELS, light_table
from ..voxgi_addon.preview.passes import material_table, principled_table
from ..voxgi_addon.scene.bvh import TEXTURE_WIDTH
from ..voxgi_addon.scene.geometry import world_triangles
from ..voxgi_addon.scene.glass import ray_alpha
from ..voxgi_addon.scene.textures import pack_atlas
from .gpu_bvh import GPUBVH, absent_lights, has_metals, shared_bvh
from .gpu_gather import drop_shared_cache, no_texture_inputs, principled_materials_texture
from .gpu_ltc import ltc_texture
from .gpu_principled import lut_texture
from .gpu_shaders import note_upload
from .gpu_volume import float_texture

# What ``uploaded`` names: the parts of a scene.
# Scene parts go in one per step (a ``view_draw``'s one upload), but consecutive small ones
# together while their bytes stay within PART_BYTES: the demo box's 11 parts took 11 draws
# before its first GI image, each sending 0.1–1 ms of tables (docs/gi_pipeline.md "Kernels
# compiled before the view needs them"); a megabyte takes about a millisecond to send
PART_BYTES = 1 << 20
WAITING = "waiting"  # what an ``upload_steps`` step that sent nothing (the BVH building) yields
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


def _bvh_fits(plan, sent: int) -> bool:
    """Whether ``plan``'s BVH is built and goes in with a step that has sent ``sent`` bytes
    (within ``PART_BYTES``; an unchanged BVH sends nothing)."""
    if not plan.bvh_ready.is_set() or plan.bvh_error is not None:
        return False
    if plan.bvh is None or plan.bvh[1] is None:
        return True
    return sent + plan.bvh[1][0].nbytes <= PART_BYTES


def _table_texture(table: np.ndarray):
    """An RGBA32F texture of a (rows, texels, 4) table (texels wide)."""
    return float_texture(table, (table.shape[1], table.shape[0]))


def lamp_tables(lights) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """(every lamp's table, one table per lamp index, the no-lamp table), from one
    ``light_table``. A lamp's table is its own row alone (row 0; its samples keep their stream,
    which its index in the row seeds), so that a dispatch of one lamp loops over one row: with
    the other lamps as padding rows, every dispatch ran the light code of every lamp, masked,
    and N lamps cost N² (docs/gi_pipeline.md "Many lamps"). The no-lamp table, and a lamp's
    that has no row, is one padding row (type −1)."""
    table = light_table(lights)

    def only(index):
        kept = table if index is None else table[table[:, 0, 3] == index]
        if len(kept) == 0:
            kept = np.zeros((1, LIGHT_TEXELS, 4), np.float32)
            kept[0, 0, 0] = -1.0
        return np.asarray(kept, np.float32)

    return only(None), [only(i) for i in range(len(lights))], only(-1)


@dataclasses.dataclass
class ScenePlan:
    """What ``GPUScene.prepare`` made of a snapshot on the CPU for ``GPUScene.upload_steps``:
    the scene's keys it was made against (``base``) and its keys after it (``keys``), and for
    each part whose key changed its tables (None: unchanged)."""

    base: dict
    keys: dict
    seconds: dict
    meshes: dict = dataclasses.field(default_factory=dict)
    tris: object = None
    bvh: tuple | None = None          # (GPUBVH, its ``pack``: None when unchanged)
    rough: object = None
    emission: object = None
    principled: object = None
    textures: str | None = None       # "none": the 1 × 1 stand-ins
    atlas: object = None
    texture_table: tuple | None = None  # (texels, rows)
    materials: tuple | None = None    # principled_materials_texture's arguments
    lamps: tuple | None = None        # lamp_tables
    lights: list = dataclasses.field(default_factory=list)
    world: object = None              # world_table
    sun: object = None                # light_tables of the map's sun lamp and its shadow ray
    emitters: object = None           # emitter_table
    # set once ``bvh`` is in (``prepare``'s on_tables: it is built on a thread meanwhile)
    bvh_ready: threading.Event = dataclasses.field(default_factory=threading.Event)
    bvh_error: BaseException | None = None
    # the scene's textures once ``upload_steps`` has sent this plan's (name → GPU texture; the
    # scene's own when it sends none): what the viewport's quick image draws its G-buffer
    # with before the plan is the scene's (``viewport_prepare``)
    textures_sent: dict | None = None

    @property
    def parts(self) -> int:
        """Scene parts ``upload_steps`` will send at most (the BVH's three textures each)."""
        building = not self.bvh_ready.is_set()
        return (sum(x is not None for x in (self.textures, self.atlas, self.texture_table,
                                            self.materials, self.lamps, self.world,
                                            self.emitters))
                + (3 if building or self.bvh is not None and self.bvh[1] is not None else 0)
                + 1)


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
        # the map's sun as a lamp (world_light.sun_lamp) and as its one shadow ray (sun_shadow),
        # None: none
        self.sun_table = self.sun_shadow_table = None
        self.lamp_tables: list = []
        self.keys: dict[str, object] = {}
        self.uploaded: dict[str, int] = {}
        self.seconds: dict[str, float] = {}
        self._meshes: dict[int, tuple[object, str]] = {}  # id(MeshData) → (it, its digest)
        self.serial = 0  # bumped by every upload_steps: an older one still running then stops

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
        key, self._meshes = self._geometry_key(snapshot)  # only this snapshot's meshes stay
        return key

    def _geometry_key(self, snapshot) -> tuple[str, dict]:
        """(``geometry_key``, the meshes' digests to keep): reads ``_meshes``, changes
        nothing (``prepare`` runs it on the worker)."""
        meshes = {}
        for obj in snapshot.objects:
            mesh = snapshot.meshes.get(obj.mesh)
            if mesh is None or id(mesh) in meshes:
                continue
            known = self._meshes.get(id(mesh))
            meshes[id(mesh)] = known if known is not None and known[0] is mesh else \
                (mesh, _mesh_digest(mesh))
        objects = tuple(
            (o.name, o.mesh, o.kind, o.armature, np.asarray(o.world_matrix, np.float64),
             getattr(o, "visibility", None), getattr(o, "holdout", None),
             tuple(getattr(o, "materials", ())),
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
        return digest(objects, armatures, textures,
                      tuple(getattr(snapshot, "holdout_materials", ()))), meshes

    def cheap(self, snapshot) -> bool:
        """Whether ``prepare(snapshot)`` is cheap (about a millisecond): the triangles and
        the world are the uploaded ones (a lamp, a material or the view changed), so no
        triangles, BVH, texture atlas or world table are built. Main thread (it reads the
        meshes' digests)."""
        if self.tris is None or "world" not in self.keys:
            return False
        if self._geometry_key(snapshot)[0] != self.keys.get("geometry"):
            return False
        world = snapshot.world
        key = None if world.radiance is None else (world.key or digest(world.radiance))
        return key == self.keys["world"][0]

    # ------------------------------------------------------------------ update

    def update(self, snapshot, on_triangles=None) -> GPUScene:
        """Make the scene ``snapshot``'s: rebuild and upload the parts whose content changed
        (``uploaded`` says which). The triangles may be empty (nothing is then built for them;
        the caller decides what an empty scene means). ``prepare`` and ``upload_steps`` in
        one call; on_triangles : ``prepare``'s."""
        for _ in self.upload_steps(self.prepare(snapshot, on_triangles=on_triangles)):
            pass
        return self

    def prepare(self, snapshot, on_geometry=None, on_tables=None,
                on_triangles=None) -> ScenePlan:
        """The CPU half of ``update``: the content keys of ``snapshot``'s parts and, for those
        that differ from the uploaded ones, their tables (world-space triangles, packed BVH,
        texture atlas, material, light, world and emitter tables) — numpy only, nothing sent to
        the GPU and nothing of the scene changed, so it may run on the worker thread while the
        main thread draws (the viewport: docs/gi_pipeline.md "Entering Rendered mode").
        on_geometry : called with (triangles, roughness table, textured, ``principled_table``)
        as soon as those are known, before the BVH is built (the viewport's vertex arrays).
        on_triangles : called with the triangles as soon as they are known, before the BVH
        is built (F12: the radiance cache's layout made on a thread meanwhile).
        on_tables : called with the plan once every part but the BVH is in it (its lights
        list, so the kernels' variants, included); the BVH is then built on a thread of its own
        meanwhile (``ScenePlan.bvh_ready``), so the caller can send the other parts and compile
        the kernels while it builds (docs/gi_pipeline.md "Entering Rendered mode")."""
        keys, seconds = dict(self.keys), {}
        plan = ScenePlan(base=dict(self.keys), keys=keys, seconds=seconds)
        plan.bvh_ready.set()  # (cleared while a thread builds it)
        world = snapshot.world
        world_key = None if world.radiance is None else (world.key or digest(world.radiance))
        lighting = None
        if world_key is not None and world_key != (keys.get("tail") or (None,) * 3)[2]:
            # a new world's light (its irradiance table: 0.5–0.9 s of numpy) is built on a
            # second thread meanwhile; scene_lights below finds it in world_light's cache
            lighting = threading.Thread(target=world_light, args=(world,),
                                        name="VoxGI world light", daemon=True)
            lighting.start()
        t0 = time.perf_counter()
        geometry, plan.meshes = self._geometry_key(snapshot)
        tris = self.tris
        if geometry != keys.get("geometry") or tris is None:
            tris = world_triangles(snapshot)
            keys["geometry"] = geometry
        plan.tris = tris
        seconds["geometry"] = time.perf_counter() - t0
        if on_triangles is not None and len(tris):
            on_triangles(tris)
        building = None
        if len(tris):
            # identity check first (free); another user of the shared BVH (the Fast path) may
            # have uploaded other triangles since, which a content comparison then catches
            bvh = self._own_bvh or shared_bvh()  # gpu_bvh.release may have made a new one

            def build():
                t0 = time.perf_counter()
                try:
                    packed = bvh.pack(tris)
                    if packed is not None:
                        seconds["bvh"] = time.perf_counter() - t0
                    plan.bvh = (bvh, packed)
                except BaseException as error:  # noqa: BLE001 - raised by prepare below
                    plan.bvh_error = error
                finally:
                    plan.bvh_ready.set()

            if on_tables is None:
                build()
            else:  # built beside the other tables (on_tables), from as soon as the
                # triangles are known: it is the longest part, the one the first image waits
                # for (the vertex arrays of on_geometry are made meanwhile)
                plan.bvh_ready.clear()
                building = threading.Thread(target=build, name="VoxGI BVH build", daemon=True)
                building.start()
        _, rough, _, emission = material_table(snapshot)
        principled = principled_table(snapshot)
        surface = getattr(tris, "textures", None)
        if on_geometry is not None:
            on_geometry(tris, rough, surface is not None, principled)
        self._prepare_textures(plan, tris, geometry)
        slots = None if surface is None else surface.slots
        variants = (None, None) if surface is None else (surface.param_slots, surface.variants)
        glow = (None, None) if surface is None else \
            (surface.emission_slots, surface.emission_strength)
        materials = digest(rough, emission, *principled, slots, *variants, *glow)
        plan.rough, plan.emission, plan.principled = rough, emission, principled
        if materials != keys.get("materials"):
            plan.materials = (principled, emission, slots, variants, glow)
            keys["materials"] = materials

        t0 = time.perf_counter()
        lamps = list(snapshot.lights)
        every, each, none = lamp_tables(lamps)
        lamp_key = digest(len(lamps), every)
        if lamp_key != keys.get("lights"):
            plan.lamps = (every, each, none)
            keys["lights"] = lamp_key
            seconds["lights"] = time.perf_counter() - t0

        # the world and the emitters follow the lamps in the lights list; their streams are
        # their indices there
        t0 = time.perf_counter()
        tail_key = (geometry, materials, world_key)
        tail = self._tail
        if lighting is not None:
            lighting.join()
        if tail_key != keys.get("tail"):
            tail = scene_lights(snapshot, tris, emission)[len(lamps):]
            keys["tail"] = tail_key
        plan.lights = lamps + tail
        found = {light.type: (light, index) for index, light in enumerate(plan.lights)
                 if light.type in ("WORLD", "EMITTERS")}
        sky, stream = found.get("WORLD", (None, 0))
        key = (world_key, stream)
        if key != keys.get("world"):
            plan.world = world_table(sky, stream)
            keys["world"] = key
            seconds["world"] = time.perf_counter() - t0
        # the map's sun as a lamp, for the pixels' glossy lobes; its samples' stream follows
        # the lights list's
        key = (world_key, len(plan.lights))
        if key != keys.get("sun"):
            sun = sun_lamp(sky)
            plan.sun = tuple(light_table([] if sun is None else [lamp], len(plan.lights))
                             for lamp in (sun, sun_shadow(sun)))
            keys["sun"] = key
        t0 = time.perf_counter()
        emitters, stream = found.get("EMITTERS", (None, 0))
        key = (geometry, materials, stream)
        if key != keys.get("emitters_source"):
            table = emitter_table(emitters, stream)
            content = digest(table)
            if content != keys.get("emitters"):  # e.g. a non-emissive object moved
                plan.emitters = table
                keys["emitters"] = content
                seconds["emitters"] = time.perf_counter() - t0
            keys["emitters_source"] = key
        if on_tables is not None:
            on_tables(plan)
        if building is not None:
            building.join()
        if plan.bvh_error is not None:
            raise plan.bvh_error
        return plan

    def _prepare_textures(self, plan: ScenePlan, tris, geometry: str) -> None:
        """The ``textures`` part's tables for ``plan``, two textures (the gathers' kernels
        have one sampler to spare per stage, not three): ``texture_atlas``, every level of
        every texture (``scene.textures.pack_atlas``; RGBA16F, as the numpy pyramids hold half
        floats), and ``texture_table``, RGBA32F BVH_WIDTH wide: row s = texture s's table row,
        then from the row its texel (BVH_WIDTH − 1, 0) names, the triangles' corner UVs (2
        texels per triangle index: (uv0, uv1), (uv2, alpha texture or -1, alpha value):
        ``textures.glsl`` ``bvh_cutout_counts``). Keyed by the textures' content and the
        geometry (which holds the materials' texture indices and alphas); 1 × 1 stand-ins
        without textures."""
        t0 = time.perf_counter()
        keys = plan.keys
        surface = getattr(tris, "textures", None) if tris is not None else None
        if surface is None:
            if keys.get("textures") != "none":
                plan.textures = "none"
                keys["textures"] = "none"
                keys.pop("texture_table", None)
            return
        key = digest(tuple((t.key or digest(t.pixels), t.interpolation, t.extension, t.srgb_bytes,
                            np.asarray(t.uv_transform, np.float64)) for t in surface.textures))
        atlas = table = None
        if key != keys.get("textures"):
            atlas, table = pack_atlas(surface.textures)
            plan.atlas = atlas
            keys["textures"] = key
        if (key, geometry) != keys.get("texture_table"):
            if table is None:
                table = pack_atlas(surface.textures)[1]
            uvs = np.asarray(surface.uvs, np.float32).reshape(-1, 6)
            texels = np.zeros((len(uvs), 2, 4), np.float32)
            texels[:, 0], texels[:, 1, :2] = uvs[:, :4], uvs[:, 4:]
            if surface.alpha_slots is not None:
                row = surface.row_of(tris.materials)
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
            plan.texture_table = (out, rows)
            keys["texture_table"] = (key, geometry)
        plan.seconds["textures"] = time.perf_counter() - t0

    def upload_steps(self, plan: ScenePlan):
        """The GPU half of ``update``: send what ``plan`` (``prepare``) rebuilt, a part per
        step (a generator: the texture atlas, the texture table, the materials, the constants,
        the lamps' tables, the world, the emitters, the BVH's three textures — consecutive
        ones together while their bytes stay within ``PART_BYTES``; a step while the BVH is
        still building yields ``WAITING`` and sends nothing; each step's parts counted as one
        by ``gpu_shaders.note_upload``), then make the scene the plan's at once, so a scene left
        between two steps is still the previous one throughout. Main thread. A plan prepared
        against other keys than the scene's (another update came first) is dropped, and so is
        this one when another ``upload_steps`` (F12's update) starts before it ends:
        ``keys == plan.keys`` afterwards says whether it went in."""
        self.serial += 1
        serial = self.serial
        self.uploaded = {}
        if plan.base != self.keys:
            return  # stale: prepared against another state of the scene
        seconds = plan.seconds
        new: dict[str, object] = {}
        sent: dict[str, int] = {}

        step = [0]  # bytes sent in this step

        def send(part: str, nbytes: int) -> None:
            if not step[0]:
                note_upload(part)  # one scene part a step: the small ones sent with it are its
            step[0] += max(int(nbytes), 1)
            sent[part] = sent.get(part, 0) + int(nbytes)

        def full(nbytes: int) -> bool:
            """Whether a part of ``nbytes`` waits for the next step (``PART_BYTES``)."""
            if step[0] and step[0] + nbytes > PART_BYTES:
                step[0] = 0
                return True
            return False

        textures = dict(self.textures)
        # (known from the last texture part's step on: ``ScenePlan.textures_sent``)
        last = "table" if plan.texture_table is not None else \
            "atlas" if plan.atlas is not None else "none"
        if plan.textures == "none":
            textures = no_texture_inputs()
            send("textures", 32)
            if last == "none":
                plan.textures_sent = textures
        if plan.atlas is not None:
            atlas = plan.atlas
            if full(atlas.size * 2):
                yield
            textures["texture_atlas"] = float_texture(atlas, (atlas.shape[1], atlas.shape[0]),
                                                      "RGBA16F")
            send("textures", atlas.size * 2)
            if last == "atlas":
                plan.textures_sent = textures
        if plan.texture_table is not None:
            out, rows = plan.texture_table
            if full(out.nbytes):
                yield
            if serial != self.serial:
                return
            textures["texture_table"] = float_texture(out, (TEXTURE_WIDTH, rows))
            send("textures", out.nbytes)
            plan.textures_sent = textures
        plan.textures_sent = textures
        if plan.materials is not None:
            principled, emission, slots, variants, glow = plan.materials
            if full(5 * len(principled[0]) * 16):
                yield
            if serial != self.serial:
                return
            t0 = time.perf_counter()
            new["materials"] = principled_materials_texture(principled, emission, slots,
                                                            variants, glow)
            send("materials", 5 * len(principled[0]) * 16)
            seconds["materials"] = seconds.get("materials", 0.0) + time.perf_counter() - t0
        lut = lut_texture()  # constant; cached by gpu_principled
        if lut is not self.lut or self.no_world is None:
            nbytes = lut.width * lut.height * 16
            none = (world_table(None, 0), emitter_table(None, 0))
            if self.no_world is None:
                nbytes += sum(_texture_bytes(table) for table in none)
            if full(nbytes):
                yield
            if serial != self.serial:
                return
            new["lut"] = lut
            if self.no_world is None:
                new["no_world"], new["no_emitters"] = (_table_texture(table) for table in none)
            ltc_texture()  # the glossy kernels' constant table (cached by gpu_ltc)
            send("constants", nbytes)
        if plan.lamps is not None:
            every, each, none = plan.lamps
            nbytes = sum(_texture_bytes(t) for t in (every, *each, none))
            if full(nbytes):
                yield
            if serial != self.serial:
                return
            new["lamp_table"] = _table_texture(every)
            new["lamp_tables"] = [_table_texture(table) for table in each]
            new["no_lamp"] = _table_texture(none)
            send("lights", nbytes)
        if plan.world is not None:
            if full(_texture_bytes(plan.world)):
                yield
            if serial != self.serial:
                return
            new["world_map"] = _table_texture(plan.world)
            send("world", _texture_bytes(plan.world))
        if plan.sun is not None:
            shown = len(plan.sun[0]) > 0
            new["sun_table"], new["sun_shadow_table"] = (
                _table_texture(table) if shown else None for table in plan.sun)
            if shown:
                send("sun", sum(_texture_bytes(table) for table in plan.sun))
        if plan.emitters is not None:
            if full(_texture_bytes(plan.emitters)):
                yield
            if serial != self.serial:
                return
            new["emitters"] = _table_texture(plan.emitters)
            send("emitters", _texture_bytes(plan.emitters))
        if step[0] and not _bvh_fits(plan, step[0]):  # the step of the last parts ends here
            step[0] = 0
            yield
            if serial != self.serial:
                return
        # the BVH last: it may still be building (``prepare``'s on_tables) while the other
        # parts go in; a step that finds it building sends nothing
        while not plan.bvh_ready.is_set() or plan.bvh_error is not None:
            yield WAITING  # (a failed build: ``prepare`` raises it, the caller drops the plan)
            if serial != self.serial:
                return
        bvh = self._own_bvh or shared_bvh()  # gpu_bvh.release may have made a new one
        if plan.bvh is not None:
            if serial != self.serial:
                return
            t0 = time.perf_counter()
            bvh, packed = plan.bvh
            # the BVH knows its own triangles (a content check): it may go in on its own
            # (a BVH built by now whose bytes fit the step of the last parts goes in with them:
            # the demo box's whole scene in one step)
            for _ in bvh.upload_steps(plan.tris, packed, PART_BYTES, sent=step[0]):
                yield
                if serial != self.serial:
                    return
            if bvh.uploaded_bytes:
                sent["bvh"] = bvh.uploaded_bytes
                seconds["bvh"] = seconds.get("bvh", 0.0) + time.perf_counter() - t0
        if serial != self.serial:
            return
        # the plan's scene, all at once
        for name, value in new.items():
            setattr(self, name, value)
        self.textures = textures
        self.bvh = bvh
        self.tris, self._meshes = plan.tris, plan.meshes
        self.rough, self.emission, self.principled = plan.rough, plan.emission, plan.principled
        surface = getattr(self.tris, "textures", None)
        self.slots = None if surface is None else surface.slots
        self.bvh.surface = dict(textures) if getattr(surface, "cutout", None) is not None \
            else {}  # cut-outs read their Alpha there
        self.lights = plan.lights
        self._tail = plan.lights[len(self.lamp_tables):]
        self.keys = dict(plan.keys)
        self.uploaded = sent
        self.seconds.update(seconds)

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

    @property
    def traces_extra_rays(self) -> bool:
        """Whether the world's and emitters' dispatch traces shadow rays where the world's rest
        is given (``direct_light_texture``'s world_hidden): for the emitters, or a map's sun;
        else ``gpu_compose.shade_stages`` runs ``world_given.glsl`` instead."""
        return any(light.type == "EMITTERS" or (light.type == "WORLD" and light.sun is not None)
                   for light in self.lights)

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
                "bvh_absent": self.absent}

    @property
    def absent(self) -> tuple[str, ...]:
        """The kinds of light the scene has none of (``absent_lights``): its one variant of
        the BVH kernels, the gathers' and every direct-light dispatch's."""
        return absent_lights(self.lights, has_metals(self.principled, self.tris))

    @property
    def direct_absent(self) -> tuple[str, ...]:
        """``absent`` of the direct-light dispatches (``absent_lights``' direct): every one of
        them takes this variant."""
        return absent_lights(self.lights, has_metals(self.principled, self.tris), direct=True)

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
    # state"): the next render builds the new file's scene, and its radiance cache.
    global _current
    _current = None
    drop_shared_cache()


def release() -> None:
    """Drop the current scene's textures and the load handler (unregister, exit)."""
    global _current
    _current = None
    if _drop_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_drop_on_load)

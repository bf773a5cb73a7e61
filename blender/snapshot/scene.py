"""Take a ``SceneSnapshot`` of a Blender scene (main thread only).

``take_snapshot`` is the only place the engine's input is read from ``bpy``. It reads
visible mesh objects from the evaluated depsgraph (object space, Blender's loop
triangulation), their materials, skinning, armatures, lights, camera and world, and
leaves the user's scene exactly as it found it.

Mesh keys: objects with no viewport-enabled modifier and no object-linked material
slot share the key of their mesh datablock (``Mesh.name_full``), so linked duplicates
share one ``MeshData`` and one cache; any other object gets its own key
``"<object name> (modified)"`` because its evaluated mesh is its own.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import bpy
import numpy as np

from ...voxgi_addon.scene.snapshot import (
    RAY_CAMERA,
    RAY_DIFFUSE,
    RAY_GLOSSY,
    RAY_SHADOW,
    MaterialData,
    MeshData,
    ObjectData,
    SceneSnapshot,
)
from .bakes import BakeQueue, render_bakes
from .environment import read_camera, read_light, read_world
from .left_out import left_out_line, light_notes, notes_of, render_notes, type_note
from .materials import AUTO_UVS, MAX_OWN_BAKES, MaterialTable, Surface, reads_its_object
from .mesh import (
    at_corners,
    material_lookup,
    named_uvs,
    read_corner_normals,
    read_corner_uvs,
    read_positions,
    read_triangles,
    triangle_materials,
)
from .mesh_cache import MeshArrays, MeshReads, change_key
from .object_random import ObjectInputs, object_random
from .reads import count
from .skin import (
    armature_modifiers,
    deform_bone_names,
    modifier_enabled,
    read_armature,
    rest_corner_normals,
    rest_positions,
    temporary_weight_attributes,
    top_weights,
    weight_layers,
)


@dataclass
class _Entry:
    """A visible mesh object on its way into the snapshot."""

    obj: bpy.types.Object
    key: str
    kind: str
    armature: bpy.types.Object | None = None
    layers: list | None = None  # weight attributes of a skinned object


def _is_animated(obj) -> bool:
    data = obj.animation_data
    return data is not None and (
        data.action is not None or len(data.drivers) > 0 or len(data.nla_tracks) > 0
    )


def object_kind(obj, depsgraph=None) -> tuple[str, bpy.types.Object | None]:
    """('skinned', armature) with an Armature modifier enabled in ``depsgraph``'s mode
    (``skin.modifier_enabled``), ('rigid', None) if it or a parent is animated or constrained,
    else ('static', None)."""
    deformers = armature_modifiers(obj, depsgraph)
    if deformers:
        return "skinned", deformers[0].object
    node = obj
    while node is not None:
        if _is_animated(node) or len(node.constraints) > 0:
            return "rigid", None
        node = node.parent
    return "static", None


def _shares_mesh(obj, depsgraph=None) -> bool:
    """Is ``obj`` 's mesh read once for every object using it (its key the mesh's)? Not with
    modifiers, object-linked material slots, or (for up to MAX_OWN_BAKES users) a material
    whose bake depends on the object (``materials.reads_its_object``: each is baked for its
    own object, as Cycles shades each copy)."""
    if any(modifier_enabled(m, depsgraph) for m in obj.modifiers) or any(
            slot.link == "OBJECT" for slot in obj.material_slots):
        return False
    data = obj.data
    return getattr(data, "users", 0) <= 1 or data.users > MAX_OWN_BAKES or not any(
        slot.material is not None and reads_its_object(slot.material)
        for slot in obj.material_slots)


def _mesh_key(obj, used: dict[str, object], depsgraph=None) -> str:
    """The MeshData key of ``obj``; ``used`` maps keys to their source (mesh or object)."""
    source = obj.data if _shares_mesh(obj, depsgraph) else obj
    base = obj.data.name_full if source is obj.data else f"{obj.name_full} (modified)"
    key, n = base, 1
    while key in used and used[key] != source:
        key, n = f"{base} [{n}]", n + 1
    used[key] = source
    return key


def _slot_materials(obj_eval, mesh) -> list:
    slots = [slot.material for slot in obj_eval.material_slots]
    # Geometry Nodes may add materials beyond the object's slots.
    return slots + list(mesh.materials[len(slots):])


def ray_visibility(obj) -> int:
    """The ``RAY_*`` bits of the rays that see ``obj`` (Object › Visibility › Ray Visibility,
    as Cycles reads them; transmission and volume rays are not traced)."""
    return ((RAY_CAMERA if obj.visible_camera else 0) | (RAY_DIFFUSE if obj.visible_diffuse else 0)
            | (RAY_GLOSSY if obj.visible_glossy else 0) | (RAY_SHADOW if obj.visible_shadow else 0))


def is_holdout_shader(material) -> bool:
    """Does a Holdout shader feed the Surface of ``material``'s Cycles output?"""
    tree = material.node_tree if material is not None else None
    output = tree.get_output_node("CYCLES") if tree is not None else None
    surface = output.inputs.get("Surface") if output is not None else None
    return bool(surface is not None and surface.is_linked
                and surface.links[0].from_node.type == "HOLDOUT")


def _holdout_index(material, table: MaterialTable, holdouts: dict[str, int]) -> int:
    """The index of a Holdout-shader material: black to every ray (no BSDF, no emission: what
    Cycles' bounce and shadow rays meet there); camera rays see nothing at it
    (``SceneSnapshot.holdout_materials``)."""
    name = material.original.name_full
    if name not in holdouts:
        holdouts[name] = len(table.materials)
        table.materials.append(MaterialData(name=name, base_color=np.zeros(3, np.float32),
                                            roughness=1.0, metallic=0.0, specular=0.0))
    return holdouts[name]


def _read_mesh(entry: _Entry, depsgraph, table: MaterialTable, warnings: list[str],
               holdouts: dict[str, int], obj_eval=None, reads: MeshReads | None = None,
               shaders: dict[str, bool] | None = None, used: dict | None = None
               ) -> MeshData | None:
    """The MeshData of an entry's evaluated object (``obj_eval``: given for an instance, which
    only exists while the depsgraph's instances are iterated); ``holdouts`` : Holdout-shader
    materials' indices (``_holdout_index``); ``reads`` : the viewport's kept mesh reads
    (``mesh_cache``): its arrays are taken from there when still valid, else read and kept;
    ``shaders`` : material name → ``is_holdout_shader``, filled as materials are met (once
    per snapshot, not per object); ``used`` : key → the material indices its triangles use,
    filled here."""
    obj_eval = obj_eval or entry.obj.evaluated_get(depsgraph)
    change = None
    if reads is not None and entry.kind != "skinned" and not entry.key.endswith(" (instanced)"):
        change = change_key(entry.obj, obj_eval)
    arrays = reads.take(entry.key, change) if change is not None else None
    evaluated = _EvaluatedMesh(obj_eval)
    try:
        if arrays is None:
            arrays = _read_arrays(entry, evaluated.mesh, change)
            if change is not None:
                reads.put(entry.key, arrays)
        if len(arrays.triangles) == 0:
            if entry.obj.type == "MESH":  # curves without bevel or fill have no faces, as in Cycles
                warnings.append(f"Object '{entry.obj.name}' has no faces; it is left out")
            return None
        # the slots' materials (Geometry Nodes may add some): the evaluated object's own mesh
        # has them; ``to_mesh`` is only needed for the arrays, a bake or another UV map
        slot_materials = _slot_materials(obj_eval, obj_eval.data if obj_eval.type == "MESH"
                                         else evaluated.mesh)
        surface = _LazySurface(entry.key, evaluated, slot_materials, arrays,
                               arrays.uvs is not None)
        shaders = {} if shaders is None else shaders

        def holdout(material) -> bool:
            name = material.original.name_full
            if name not in shaders:
                shaders[name] = is_holdout_shader(material)
            return shaders[name]

        lookup = material_lookup(slot_materials, lambda m: _holdout_index(m, table, holdouts)
                                 if holdout(m) else table.index_of(m, surface))
        if change is not None:  # a kept mesh with the same slots' materials: the same array
            materials = reads.triangle_materials(entry.key, arrays, lookup,
                                                 lambda: triangle_materials(arrays.slots, lookup))
        else:
            materials = triangle_materials(arrays.slots, lookup)
        # the materials used, from the few slots used (not a pass over every triangle)
        indices = np.unique(triangle_materials(arrays.used_slots, lookup))
        if used is not None:
            used[entry.key] = indices
        uvs = arrays.uvs
        if surface.auto_uvs is not None:  # a bake over a layout of the polygons: its triangles
            auto = at_corners(surface.auto_uvs.ravel(), arrays.corners, 2)
            on = [int(i) for i in indices[indices >= 0] if table.uv_map(int(i)) == AUTO_UVS]
            uvs = auto if uvs is None else np.where(np.isin(materials, on)[:, None, None], auto, uvs)
        if uvs is not None and any(table.uv_map(int(i)) for i in indices[indices >= 0]):
            uvs = named_uvs(evaluated.mesh, arrays.corners, materials, table, uvs)
        skin = None
        if entry.kind == "skinned":  # the rest shape's weights
            skin = top_weights(evaluated.mesh, entry.layers, entry.armature.name_full)
        return MeshData(
            name=entry.key,
            positions=arrays.positions,
            triangles=arrays.triangles,
            triangle_materials=materials,
            uvs=uvs,
            skin=skin,
            corner_normals=arrays.corner_normals,
        )
    finally:
        evaluated.clear()


def _read_arrays(entry: _Entry, mesh, change) -> MeshArrays:
    """What of ``mesh`` (an evaluated ``to_mesh``) its geometry alone gives (``MeshArrays``);
    no triangles and nothing else read when it has no faces."""
    triangles, corners, slots = read_triangles(mesh)
    data = entry.obj.data if entry.obj.type == "MESH" else None
    # modifiers and shape keys make the evaluated mesh depend on more than its datablock
    modified = len(entry.obj.modifiers) > 0 or getattr(data, "shape_keys", None) is not None
    names = (change, entry.obj.name_full, "" if data is None else data.name_full, modified)
    if len(triangles) == 0:
        empty = np.empty((0, 3), np.float32)
        return MeshArrays(*names, empty, triangles, corners, slots, None,
                          np.empty((0, 3, 3), np.float32), np.unique(slots))
    # a skinned mesh is kept in its rest shape, which the skinning matrices pose: its bakes
    # are keyed by it too, so that a new pose bakes nothing again
    skinned = entry.kind == "skinned"
    positions = rest_positions(mesh) if skinned else read_positions(mesh)
    uvs = read_corner_uvs(mesh, corners)
    normals = rest_corner_normals(mesh, corners) if skinned else read_corner_normals(mesh, corners)
    return MeshArrays(*names, positions, triangles, corners, slots, uvs, normals,
                      np.unique(slots))


class _EvaluatedMesh:
    """An evaluated object's ``to_mesh``, made on first use (counted: ``reads.count``) and
    cleared by ``clear``."""

    def __init__(self, obj_eval):
        self.obj_eval, self._mesh = obj_eval, None

    @property
    def mesh(self):
        if self._mesh is None:
            count("meshes")
            self._mesh = self.obj_eval.to_mesh()
        return self._mesh

    def clear(self) -> None:
        if self._mesh is not None:
            self._mesh = None
            self.obj_eval.to_mesh_clear()


class _LazySurface(Surface):
    """A ``Surface`` whose evaluated mesh and content key are made only when a bake asks."""

    def __init__(self, key: str, evaluated: _EvaluatedMesh, slot_materials: list,
                 arrays: MeshArrays, has_uvs: bool):
        self.key, self.obj_eval, self.slot_materials = key, evaluated.obj_eval, slot_materials
        self.has_uvs, self._evaluated, self._arrays = has_uvs, evaluated, arrays

    @property
    def uvs_in_square(self) -> bool:
        uvs = self._arrays.uvs
        return uvs is None or len(uvs) == 0 or bool(uvs.min() >= -1e-3 and uvs.max() <= 1.0 + 1e-3)

    @property
    def mesh(self):
        return self._evaluated.mesh

    @property
    def digest(self) -> str:
        return self._arrays.digest


# Object types whose evaluated geometry is a mesh (what Cycles renders of them).
RENDERABLE = ("MESH", "CURVE", "FONT", "SURFACE", "META")
# Types Cycles renders that the preview does not (yet) are said in the report
# (left_out.type_note).


def render_disabled() -> frozenset[int]:
    """``session_uid`` of the objects in a collection disabled in renders (a collection's own
    objects, as ``renders`` reads them), for one pass over many objects: ``Object.
    users_collection`` scans every collection's objects for each object it is asked of (on the
    diorama's 61 objects 2–3 ms a call, twice or three times per update)."""
    collections = [c for c in bpy.data.collections if c.hide_render] + \
        [s.collection for s in bpy.data.scenes if s.collection.hide_render]
    return frozenset(o.session_uid for c in collections for o in c.objects)


def renders(obj, view_layer, disabled: frozenset[int] | None = None) -> bool:
    """Does Blender render ``obj`` from this view layer: visible there (not hidden, its
    collections not excluded) and not disabled in renders (the object, or a collection it is
    in)? disabled : ``render_disabled()``, taken once for many objects."""
    if not obj.visible_get(view_layer=view_layer) or obj.hide_render:
        return False
    if disabled is None:
        return not any(c.hide_render for c in obj.users_collection)
    return obj.session_uid not in disabled


def shown_objects(depsgraph):
    """Whether an (original) object of the depsgraph's view layer is shown: what Blender renders
    from it. F12's depsgraph (``mode`` 'RENDER') holds exactly what the render shows, objects
    hidden in the viewport (eye, monitor, a hidden layer collection) included; the viewport's
    holds objects it does not draw, so there it is ``renders``."""
    if depsgraph.mode == "RENDER":
        evaluated = frozenset(o.original.session_uid for o in depsgraph.objects)
        return lambda obj: obj.session_uid in evaluated
    view_layer, disabled = depsgraph.view_layer, render_disabled()
    return lambda obj: renders(obj, view_layer, disabled)


def _visible_mesh_entries(view_layer, warnings: list[str], depsgraph) -> list[_Entry]:
    entries, used = [], {}
    is_shown = shown_objects(depsgraph)
    for obj in view_layer.objects:
        shown = is_shown(obj)
        if shown and type_note(obj) is not None:
            warnings.append(left_out_line(obj.name, [type_note(obj)]))
        if obj.type not in RENDERABLE or not shown:
            continue
        kind, armature = object_kind(obj, depsgraph)
        if kind == "skinned" and obj.library is not None:
            # Reading weights needs a temporary modifier, which linked data refuses.
            warnings.append(
                f"Object '{obj.name}' is linked from a library: VoxGI cannot read its skin weights, "
                "so it is voxelized in its current pose and will not deform"
            )
            kind, armature = "rigid", None
        entry = _Entry(obj, _mesh_key(obj, used, depsgraph), kind, armature)
        if kind == "skinned":
            if len(armature_modifiers(obj, depsgraph)) > 1:
                warnings.append(f"Object '{obj.name}' has several Armature modifiers; only the first is used")
            entry.layers = weight_layers(obj, deform_bone_names(armature))
            if not entry.layers:
                warnings.append(
                    f"Object '{obj.name}' has no vertex group named after a deform bone of "
                    f"'{armature.name}'; it will not deform"
                )
        entries.append(entry)
    return entries


def read_ahead(depsgraph, reads: MeshReads, seconds: float) -> bool:
    """Read into ``reads`` the visible meshes the next snapshot would read, for about
    ``seconds`` (at least one mesh); True when none is left, so that ``take_snapshot`` with
    ``reads`` reads no mesh the kept ones can stand for. The live viewport spreads a full
    snapshot's mesh reads over its draws this way (docs/gi_pipeline.md "Snapshots that read
    only what changed"): its owner keeps ``reads`` up to date with the depsgraph's updates
    meanwhile. Skinned and instanced meshes are never kept, so they are left to the
    snapshot."""
    start = time.perf_counter()
    seen, read = set(), 0
    for entry in _visible_mesh_entries(depsgraph.view_layer, [], depsgraph):
        if entry.kind == "skinned" or entry.key in seen:
            continue
        seen.add(entry.key)
        obj_eval = entry.obj.evaluated_get(depsgraph)
        change = change_key(entry.obj, obj_eval)
        if change is None or reads.holds(entry.key, change):
            continue
        if read and time.perf_counter() - start > seconds:
            return False
        evaluated = _EvaluatedMesh(obj_eval)
        try:
            reads.keep(entry.key, _read_arrays(entry, evaluated.mesh, change))
        finally:
            evaluated.clear()
        read += 1
    return True


def take_snapshot(context_or_scene, depsgraph=None, reads: MeshReads | None = None,
                  bakes: BakeQueue | None = None) -> SceneSnapshot:
    """Read the scene into a ``SceneSnapshot`` (main thread only).

    context_or_scene : a ``bpy.types.Context`` or ``bpy.types.Scene``.
    depsgraph : the evaluated depsgraph of the view layer to read; defaults to the
        context's (``Context.evaluated_depsgraph_get()``).
    reads : the live viewport's mesh reads of its last snapshot (``mesh_cache.MeshReads``,
        kept up to date with the depsgraph's updates by its owner): a mesh whose geometry
        did not change is taken from there, not read again. None reads every mesh.
    bakes : the live viewport's queue of material bakes (``bakes.BakeQueue``): a socket Cycles
        must bake and has not is queued there, its value read meanwhile; a node-built world is
        baked by another process (``world_process``), its last map shown meanwhile. None
        bakes here, or, off the main thread (F12 in the UI), has the main thread's timer and
        a child bake them (``bakes.RenderBakes``) and reads the scene again.
    Raises VoxGIError for input the engine cannot represent (e.g. > 256 deform bones).
    The scene is restored exactly (temporary modifiers and node groups removed).
    """
    if isinstance(context_or_scene, bpy.types.Scene):
        scene = context_or_scene
    else:
        scene = context_or_scene.scene
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    if bakes is None and render_bakes.available():
        # F12 in the UI (a render thread): the bakes it needs go to the main thread's timer
        # and a child process, and the scene is read again with them (``bakes.RenderBakes``)
        queue = BakeQueue()
        snapshot = _take_snapshot(scene, depsgraph, reads, queue, None)
        if not queue.requests:
            return snapshot
        render_bakes.bake(queue, depsgraph)
        return _take_snapshot(scene, depsgraph, reads, queue, None)
    return _take_snapshot(scene, depsgraph, reads, bakes,
                          None if bakes is None else bakes.worlds)


def _take_snapshot(scene, depsgraph, reads: MeshReads | None, bakes: BakeQueue | None,
                   worlds) -> SceneSnapshot:
    """``take_snapshot`` of ``scene`` with its material bakes queued in ``bakes`` (None: baked
    here) and its world's in ``worlds`` (``world_process.WorldBakes``; None: baked here)."""
    view_layer = depsgraph.view_layer
    warnings: list[str] = []
    table = MaterialTable(warnings, queue=bakes,
                          frame=getattr(depsgraph.scene_eval, "frame_current", scene.frame_current))

    entries = _visible_mesh_entries(view_layer, warnings, depsgraph)
    skinned = {e.obj: e.layers for e in entries if e.kind == "skinned"}
    meshes: dict[str, MeshData] = {}
    read_keys: set[str] = set()
    holdouts: dict[str, int] = {}
    shaders: dict[str, bool] = {}  # material name → is_holdout_shader
    used: dict[str, np.ndarray] = {}  # mesh key → the material indices its triangles use
    origins: dict[str, object] = {}  # instanced mesh key → the instanced object

    def read_instanced(key, original, obj_eval):  # each instanced mesh once
        if key not in read_keys:
            read_keys.add(key)
            mesh = _read_mesh(_Entry(original, key, "static"), depsgraph, table, warnings,
                              holdouts, obj_eval, reads, shaders, used)
            if mesh is not None:
                meshes[key] = mesh
                origins[key] = original

    if reads is not None:
        reads.begin()
    if bakes is not None:
        bakes.begin()
    instance_inputs: list[ObjectInputs] = []
    instances = instance_objects(depsgraph, read_instanced, instance_inputs)
    with temporary_weight_attributes(skinned, depsgraph):
        for entry in entries:
            if entry.key not in read_keys:  # linked duplicates are read once
                read_keys.add(entry.key)
                mesh = _read_mesh(entry, depsgraph, table, warnings, holdouts, reads=reads,
                                  shaders=shaders, used=used)
                if mesh is not None:
                    meshes[entry.key] = mesh

    if reads is not None:
        reads.end()
    if bakes is not None:
        bakes.end()
    # Matrices are read after the temporary modifiers are gone.
    objects = mesh_objects([e for e in entries if e.key in meshes], depsgraph) + \
        [o for o in instances if o.mesh in meshes]
    object_colors: tuple = ()
    if table.varies_by_object:  # Base Colors by Object Info › Random, Color: each object's own
        inputs = [object_inputs(e.obj, depsgraph) for e in entries if e.key in meshes] + \
            [r for o, r in zip(instances, instance_inputs) if o.mesh in meshes]
        objects = with_object_materials(objects, inputs, table, used)
        if table.reads_object_color:  # what a posed snapshot checks (``pose``)
            object_colors = tuple(i.color for i in inputs)
    # what of each object (each instanced object once) the preview leaves out, once per object
    named = [(e.obj.name, e.obj, e.key) for e in entries if e.key in meshes] + \
        [(f"{origin.name} (instanced)", origin, key) for key, origin in origins.items()
         if key in meshes]
    for name, obj, key in named:
        used_here = used[key]
        notes = notes_of(obj, [table.materials[i].name for i in used_here
                               if 0 <= i < len(table.materials)], table.notes)
        if notes:
            warnings.append(left_out_line(name, notes))
    warnings.extend(render_notes(scene))
    lights = read_lights(depsgraph, warnings)
    return SceneSnapshot(
        meshes=meshes,
        materials=table.materials,
        textures=tuple(table.textures),
        objects=objects,
        armatures=read_armatures([e for e in entries if e.key in meshes], depsgraph),
        lights=lights,
        camera=read_camera(scene, depsgraph),
        world=read_world(scene, warnings, deferred=worlds, depsgraph=depsgraph),
        frame=int(scene.frame_current),
        warnings=tuple(warnings),
        holdout_materials=tuple(sorted(holdouts.values())),
        object_colors=object_colors,
        **scene_flags(scene),
    )


def mesh_objects(entries: list[_Entry], depsgraph) -> list[ObjectData]:
    """The ``ObjectData`` of visible mesh objects (``_visible_mesh_entries``) at the
    depsgraph's frame: matrix, kind, armature, ray visibility, holdout."""
    view_layer = depsgraph.view_layer
    return [ObjectData(name=e.obj.name_full, mesh=e.key, world_matrix=_world_matrix(e.obj, depsgraph),
                       kind=e.kind,
                       armature=e.armature.name_full if e.armature is not None else None,
                       visibility=ray_visibility(e.obj),
                       holdout=bool(e.obj.holdout_get(view_layer=view_layer)))
            for e in entries]


def read_armatures(entries: list[_Entry], depsgraph) -> dict:
    """The ``ArmatureData`` (rest and pose matrices of the deform bones) of every armature
    deforming one of ``entries``, by name."""
    armatures = {}
    for e in entries:
        if e.armature is not None and e.armature.name_full not in armatures:
            armatures[e.armature.name_full] = read_armature(e.armature,
                                                            e.armature.evaluated_get(depsgraph))
    return armatures


def read_lights(depsgraph, warnings: list[str] | None = None) -> list:
    """The ``LightData`` of the lights Blender renders from the view layer (``shown_objects``,
    as the meshes) at the depsgraph's frame; ``warnings`` (None: none) gets each one's
    ``light_notes``."""
    view_layer, lights = depsgraph.view_layer, []
    is_shown = None
    for obj in view_layer.objects:
        if obj.type != "LIGHT":
            continue
        if is_shown is None:
            is_shown = shown_objects(depsgraph)
        if is_shown(obj):
            light = read_light(obj, obj.evaluated_get(depsgraph))
            if light is not None:
                lights.append(light)
                note = light_notes(obj) if warnings is not None else None
                if note:
                    warnings.append(note)
    return lights


def scene_flags(scene) -> dict:
    """The scene settings a snapshot carries besides its objects (``SceneSnapshot`` fields)."""
    return {"film_transparent": bool(scene.render.film_transparent),
            "refractive_caustics": bool(getattr(getattr(scene, "cycles", None),
                                                "caustics_refractive", True))}


def instance_objects(depsgraph, read=None, inputs: list | None = None) -> list[ObjectData]:
    """The depsgraph's instances (collection instances, geometry-nodes and particle instances)
    of renderable objects: one ObjectData per instance with its own world matrix. An instance
    of a plain mesh shares the mesh datablock's key with its other users. Ray visibility is the
    instanced object's and its instancer's together, holdout the instancer's (or the object's),
    as Cycles syncs instances. ``read(key, original object, evaluated object)`` is called for
    each instance (the evaluated object only exists while the instances are iterated): the
    full snapshot reads each key's mesh there, a posed one nothing (None). ``inputs``, when
    given, gets each instance's Object Info (``object_inputs``), in order."""
    out, used = [], {}
    for inst in depsgraph.object_instances:
        if not inst.is_instance:
            continue
        obj_eval = inst.object
        original = obj_eval.original
        if obj_eval.type not in RENDERABLE or original.hide_render:
            continue
        if inst.parent is not None and inst.parent.original == original:
            continue  # a curve's or text's own evaluated geometry: read with the object itself
        plain = obj_eval.type == "MESH" and _shares_mesh(original, depsgraph) and \
            obj_eval.data is not None and obj_eval.data.name_full == original.data.name_full
        key = original.data.name_full if plain else f"{original.name_full} (instanced)"
        if read is not None:
            read(key, original, obj_eval)
        parent = inst.parent.original.name_full if inst.parent is not None else "?"
        base = f"{parent} › {original.name_full}"
        name, n = base, 1
        while name in used:
            name, n = f"{base} [{n}]", n + 1
        used[name] = True
        visibility, holdout = ray_visibility(original), original.is_holdout
        if inst.parent is not None:
            visibility &= ray_visibility(inst.parent.original)
            holdout = holdout or inst.parent.original.holdout_get(view_layer=depsgraph.view_layer)
        out.append(ObjectData(name=name, mesh=key, kind="static",
                              world_matrix=np.array(inst.matrix_world, dtype=np.float64),
                              visibility=visibility, holdout=bool(holdout)))
        if inputs is not None:
            inputs.append(ObjectInputs(object_random(original.name, inst.random_id),
                                       tuple(obj_eval.color)))
    return out


def object_inputs(obj, depsgraph) -> ObjectInputs:
    """What Object Info gives ``obj`` (an object of the view layer): its Random (a hash of its
    name, ``object_random``) and its evaluated Color."""
    return ObjectInputs(object_random(obj.name), tuple(obj.evaluated_get(depsgraph).color))


def with_object_materials(objects, inputs, table: MaterialTable, used: dict) -> list:
    """``objects`` with ``ObjectData.materials`` where a material of theirs takes its Base
    Color from Object Info: each object's variant at its own Random and Color (``inputs``,
    aligned with ``objects``; ``MaterialTable.object_material``)."""
    varying = {key: [int(i) for i in indices if table.varies(int(i))]
               for key, indices in used.items()}
    out = []
    for obj, given in zip(objects, inputs, strict=True):
        pairs = tuple((i, table.object_material(i, given)) for i in varying.get(obj.mesh, ()))
        pairs = tuple((i, j) for i, j in pairs if i != j)
        out.append(dataclasses.replace(obj, materials=pairs) if pairs else obj)
    return out


def _world_matrix(obj, depsgraph) -> np.ndarray:
    """(4, 4) float64 world matrix of the evaluated object."""
    return np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)


def snapshot_summary(snapshot: SceneSnapshot) -> dict[str, int]:
    """Counts describing a snapshot, for the panel and reports."""
    meshes = snapshot.meshes.values()
    return {
        "objects": len(snapshot.objects),
        "meshes": len(snapshot.meshes),
        "triangles": sum(len(m.triangles) for m in meshes),
        "vertices": sum(len(m.positions) for m in meshes),
        "materials": len(snapshot.materials),
        "armatures": len(snapshot.armatures),
        "lights": len(snapshot.lights),
    }

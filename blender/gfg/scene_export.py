"""Read a Blender scene into a ``GFGScene`` for ``export_scene.gfg`` (main thread).

The scene is evaluated once (the context's depsgraph); skinned meshes are read in their rest
shape with their weights through the snapshot's temporary weight attributes, and with
"apply modifiers" off every other modifier is switched off for the read. Everything is
restored afterwards. Objects become nodes parents-first, depth-first with siblings by name,
so the same scene always gives the same file.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field

import mathutils
import numpy as np

from ...voxgi_addon.errors import VoxGIError
from ...voxgi_addon.files.gfg import GFGScene, Node, VertexTypes, compose_world, voxel_set_from_result
from ...voxgi_addon.files.gfg.spec import BoneFlag, NodeKind
from ..session import peek_session
from ..snapshot.skin import armature_modifiers, temporary_weight_attributes, top_weights
from .armature import export_animation, export_pose, export_skeleton
from .material import export_material
from .mesh import export_mesh

EXPORTED_TYPES = ("MESH", "ARMATURE", "EMPTY")
MAX_SKIN_BONE_INDEX = 255  # the snapshot's top-4 weights carry uint8 bone indices


@dataclass
class ExportOptions:
    selected_only: bool = False
    apply_modifiers: bool = True
    include_skeleton: bool = True
    include_animation: bool = True
    sample_animation: bool = True
    include_voxel_caches: bool = True
    include_probes: bool = True
    vertex_types: VertexTypes = field(default_factory=VertexTypes)
    interleaved: bool = True


def _exported_objects(view_layer, options: ExportOptions) -> list:
    """Objects to export, parents first (depth-first, siblings by name)."""
    chosen = {o for o in view_layer.objects if o.type in EXPORTED_TYPES and o.visible_get(view_layer=view_layer)
              and (not options.selected_only or o.select_get(view_layer=view_layer))}
    if options.include_skeleton:  # armatures deforming exported meshes come along
        chosen |= {m.object for o in list(chosen) if o.type == "MESH" for m in armature_modifiers(o)}
    ordered = []

    def visit(objs):
        for obj in sorted(objs, key=lambda o: o.name_full):
            ordered.append(obj)
            visit([c for c in obj.children if c in chosen])

    visit([o for o in chosen if o.parent not in chosen])
    return ordered


def _rotation_xyz(obj) -> np.ndarray:
    """The object's rotation as Euler XYZ radians (other modes converted)."""
    mode = obj.rotation_mode
    if mode == "XYZ":
        euler = obj.rotation_euler
    elif mode == "QUATERNION":
        euler = obj.rotation_quaternion.to_euler("XYZ")
    elif mode == "AXIS_ANGLE":
        angle, *axis = obj.rotation_axis_angle
        euler = mathutils.Quaternion(axis, angle).to_euler("XYZ")
    else:
        euler = obj.rotation_euler.to_matrix().to_euler("XYZ")
    return np.array(euler[:], np.float32)


def _node(obj, obj_eval, parent: int) -> Node:
    node = Node(obj.name_full, parent)
    has_deltas = any(obj.delta_location) or any(obj.delta_rotation_euler) or \
        tuple(obj.delta_scale) != (1.0, 1.0, 1.0) or tuple(obj.delta_rotation_quaternion) != (1.0, 0.0, 0.0, 0.0)
    if parent < 0 and obj.parent is not None:  # parent not exported: keep the world transform
        location, rotation, scale = obj_eval.matrix_world.decompose()
        node.translation, node.scale = np.float32(location[:]), np.float32(scale[:])
        node.rotation = np.float32(rotation.to_euler("XYZ")[:])
    elif has_deltas:
        location, rotation, scale = obj_eval.matrix_basis.decompose()
        node.translation, node.scale = np.float32(location[:]), np.float32(scale[:])
        node.rotation = np.float32(rotation.to_euler("XYZ")[:])
    else:
        node.translation = np.array(obj_eval.location[:], np.float32)
        node.rotation = _rotation_xyz(obj_eval)
        node.scale = np.array(obj_eval.scale[:], np.float32)
    if parent >= 0:
        node.parent_inverse = np.array(obj.matrix_parent_inverse, np.float32)
    return node


@contextmanager
def _modifiers_off(objects, keep_armature: bool, depsgraph):
    """Viewport modifiers of ``objects`` switched off (Armature ones too unless ``keep_armature``:
    with the skeleton exported, the skin reader switches those off itself), ``depsgraph``
    re-evaluated on entry and exit."""
    switched = [m for o in objects for m in o.modifiers
                if m.show_viewport and not (keep_armature and m.type == "ARMATURE")]
    try:
        for m in switched:
            m.show_viewport = False
        if switched:
            depsgraph.update()
        yield
    finally:
        for m in switched:
            m.show_viewport = True
        if switched:
            depsgraph.update()


class _Exporter:
    def __init__(self, context, options: ExportOptions, directory: str):
        self.context, self.options, self.directory = context, options, directory
        self.scene = context.scene
        self.depsgraph = context.evaluated_depsgraph_get()
        self.view_layer = self.depsgraph.view_layer
        self.warnings: list[str] = []
        self.gfg = GFGScene()
        self.materials: dict[str, int] = {}
        self.skeletons: dict[str, int] = {}  # armature data name → skeleton index

    def material_index(self, material) -> int:
        if material is None:
            return -1
        key = material.original.name_full
        if key not in self.materials:
            self.materials[key] = len(self.gfg.materials)
            self.gfg.materials.append(export_material(material.original, self.directory, self.warnings))
        return self.materials[key]

    def skeleton_index(self, armature_obj) -> int:
        key = armature_obj.data.name_full
        if key not in self.skeletons:
            self.skeletons[key] = len(self.gfg.skeletons)
            self.gfg.skeletons.append(export_skeleton(self.scene, self.view_layer, armature_obj, self.warnings))
        return self.skeletons[key]

    def mesh_key(self, obj, sources: dict) -> str:
        """The GFG mesh name of a mesh object: its mesh's name (shared by linked duplicates), or
        ``"<object> (modified)"`` for an object whose evaluated mesh is its own; ``sources``
        maps keys to what they stand for, so two different sources never share a key."""
        own = any(m.show_viewport and (m.type != "ARMATURE" or not self.options.include_skeleton)
                  for m in obj.modifiers) and self.options.apply_modifiers
        own = own or any(slot.link == "OBJECT" for slot in obj.material_slots)
        source = obj if own else obj.data
        base = f"{obj.name_full} (modified)" if own else obj.data.name_full
        key, n = base, 1
        while sources.setdefault(key, source) != source:
            key, n = f"{base} [{n}]", n + 1
        return key

    def skin_layers(self, obj, armature) -> list:
        skeleton = self.gfg.skeletons[self.skeleton_index(armature)]
        groups = obj.vertex_groups
        layers = [(i, n, f"__voxgi_weight_{i}") for i, n in enumerate(skeleton.bone_names)
                  if int(skeleton.flags[i]) & BoneFlag.DEFORM and groups.get(n) is not None]
        if layers and layers[-1][0] > MAX_SKIN_BONE_INDEX:
            raise VoxGIError(f"Armature '{armature.name}' has more than {MAX_SKIN_BONE_INDEX + 1} bones: "
                             "GFG export of its skinned meshes supports 256")
        return layers

    def run(self) -> GFGScene:
        objects = _exported_objects(self.view_layer, self.options)
        index = {o: i for i, o in enumerate(objects)}
        skinned = {}
        for obj in objects:
            deformers = armature_modifiers(obj) if obj.type == "MESH" and self.options.include_skeleton else []
            if deformers:
                skinned[obj] = (deformers[0].object, self.skin_layers(obj, deformers[0].object))
        for obj in objects:
            if obj.type == "ARMATURE" and self.options.include_skeleton:
                self.skeleton_index(obj)
        if self.skeletons:
            self.depsgraph.update()  # reading bones toggled edit mode
        sources: dict = {}  # keys first: the temporary modifiers below change what mesh_key sees
        keys = {obj: self.mesh_key(obj, sources) for obj in objects if obj.type == "MESH"}
        meshes: dict[str, int] = {}
        off = [] if self.options.apply_modifiers else [o for o in objects if o.type == "MESH"]
        weights = {o: layers for o, (_, layers) in skinned.items()}
        with _modifiers_off(off, self.options.include_skeleton, self.depsgraph), \
                temporary_weight_attributes(weights, self.depsgraph):
            for obj in objects:
                node = _node(obj, obj.evaluated_get(self.depsgraph), index.get(obj.parent, -1))
                self.gfg.nodes.append(node)
                if obj.type == "MESH":
                    node.kind = NodeKind.MESH
                    key = keys[obj]
                    if key not in meshes:
                        meshes[key] = len(self.gfg.meshes)
                        self.gfg.meshes.append(self.read_mesh(obj, key, skinned.get(obj)))
                    node.mesh = meshes[key]
                    if obj in skinned:
                        node.armature_node = index[skinned[obj][0]]
        self.finish(objects, index)
        return self.gfg

    def read_mesh(self, obj, key, skin):
        obj_eval = obj.evaluated_get(self.depsgraph)
        mesh = obj_eval.to_mesh()
        try:
            slots = [s.material for s in obj_eval.material_slots] + list(mesh.materials[len(obj_eval.material_slots):])

            def slot_materials(count, used):
                result = np.full(count, -1, np.int64)
                for s in used:
                    result[s] = self.material_index(slots[s] if s < len(slots) else None)
                return result

            skin_data, skeleton = None, -1
            if skin is not None:
                armature, layers = skin
                skeleton = self.skeleton_index(armature)
                skin_data = top_weights(mesh, layers, armature.name_full)
            return export_mesh(key, mesh, slot_materials, skin_data, skeleton,
                               self.options.vertex_types, self.options.interleaved)
        finally:
            obj_eval.to_mesh_clear()

    def finish(self, objects, index) -> None:
        """Armature nodes, poses, animations, world matrices, caches and probes."""
        fps = self.scene.render.fps / self.scene.render.fps_base
        for obj, node in zip(objects, self.gfg.nodes):
            obj_eval = obj.evaluated_get(self.depsgraph)
            if obj.type != "ARMATURE" or not self.options.include_skeleton:
                continue
            node.kind, node.skeleton = NodeKind.ARMATURE, self.skeleton_index(obj)
            skeleton = self.gfg.skeletons[node.skeleton]
            node.pose = export_pose(obj_eval, skeleton)
            if self.options.include_animation:
                animation = export_animation(obj, skeleton, node.skeleton, index[obj], fps,
                                             self.options.sample_animation, self.warnings)
                if animation is not None:
                    self.gfg.animations.append(animation)
        compose_world(self.gfg.nodes)
        session = peek_session(self.scene.name_full)
        if self.options.include_voxel_caches and session is not None and session.caches is not None:
            self.gfg.voxels = voxel_set_from_result(session.caches)
        from ..probe_store import load_grids  # baked probes, from the session or the .blend

        probes = load_grids(self.scene) if self.options.include_probes else []
        if probes:
            self.gfg.probe_grids = list(probes)


def export_scene(context, options: ExportOptions, directory: str) -> tuple[GFGScene, list[str]]:
    """The context's scene as a ``GFGScene`` and the warnings gathered on the way.

    directory : the target file's folder (texture paths are made relative to it).
    Raises VoxGIError for scenes the format cannot hold (e.g. > 256 bones for a skinned mesh).
    """
    exporter = _Exporter(context, options, directory)
    exporter.run()
    return exporter.gfg, exporter.warnings

"""Build Blender data from a ``GFGScene`` for ``import_scene.gfg`` (main thread).

Materials, meshes (one vertex per GFG vertex, free custom normals), armatures with their
rest bones, pose and animation, and objects with the stored transforms and parenting. Voxel
caches and probe grids go to the add-on session of the scene, copied out of the file so the
file is not kept mapped (a mapped file cannot be overwritten on Windows).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import bpy
import mathutils
import numpy as np

from ...voxgi_addon.files.gfg import GFGScene, voxel_set_to_result
from ...voxgi_addon.files.gfg.spec import NodeKind
from ...voxgi_addon.voxelize.cache import VoxelCache
from ..session import scene_session
from .armature import apply_pose, import_animation, import_skeleton
from .material import import_material
from .mesh import assign_weights, import_mesh


@dataclass
class ImportOptions:
    import_animation: bool = True
    attach_voxel_caches: bool = True
    attach_probes: bool = True


@dataclass
class ImportSummary:
    objects: list
    meshes: int = 0
    materials: int = 0
    armatures: int = 0
    animations: int = 0
    voxel_caches: int = 0
    probe_grids: int = 0


def _copied(cache: VoxelCache) -> VoxelCache:
    arrays = {f: None if getattr(cache, f) is None else np.array(getattr(cache, f))
              for f in ("origin_cell", "dims", "positions", "normals", "colors", "weights", "bone_indices")}
    return VoxelCache(cache.key, cache.cascade, cache.span, **arrays)


def _new_object(gfg_node, data, collection):
    obj = bpy.data.objects.new(gfg_node.name, data)
    collection.objects.link(obj)
    obj.rotation_mode = "XYZ"
    obj.location = gfg_node.translation.tolist()
    obj.rotation_euler = gfg_node.rotation.tolist()
    obj.scale = gfg_node.scale.tolist()
    return obj


def import_scene(context, gfg: GFGScene, options: ImportOptions, directory: str,
                 warnings: list[str]) -> ImportSummary:
    """Add everything ``gfg`` holds to the context's scene (objects into the active collection)."""
    scene = context.scene
    collection = context.collection or scene.collection
    materials = [import_material(m, directory, warnings) for m in gfg.materials]
    meshes = []
    for m in gfg.meshes:
        try:
            meshes.append(import_mesh(m, materials))
        except ValueError as error:
            warnings.append(f"{error}; it is left out")
            meshes.append(None)
    armature_data: dict[int, bpy.types.Armature] = {}
    objects = []
    for n in gfg.nodes:
        data, new_armature = None, False
        if n.kind == NodeKind.MESH and meshes[n.mesh] is not None:
            data = meshes[n.mesh][0]
        elif n.kind == NodeKind.ARMATURE:
            data = armature_data.get(n.skeleton)
            if data is None:  # nodes sharing a skeleton share its armature data
                new_armature = True
                data = armature_data[n.skeleton] = bpy.data.armatures.new(gfg.skeletons[n.skeleton].name)
        obj = _new_object(n, data, collection)
        if new_armature:
            import_skeleton(scene, obj, gfg.skeletons[n.skeleton], warnings)
        if n.parent >= 0:
            obj.parent = objects[n.parent]
            obj.matrix_parent_inverse = mathutils.Matrix(np.asarray(n.parent_inverse, np.float64).tolist())
        objects.append(obj)
    for n, obj in zip(gfg.nodes, objects):
        if n.kind == NodeKind.ARMATURE and n.pose is not None:
            apply_pose(obj, gfg.skeletons[n.skeleton], n.pose)
        if n.kind == NodeKind.MESH and n.armature_node >= 0 and meshes[n.mesh] is not None \
                and gfg.meshes[n.mesh].skeleton >= 0:
            skeleton = gfg.skeletons[gfg.meshes[n.mesh].skeleton]
            assign_weights(obj, meshes[n.mesh][1], skeleton.bone_names)
            modifier = obj.modifiers.new("Armature", "ARMATURE")
            modifier.object = objects[n.armature_node]
    summary = ImportSummary(objects, sum(m is not None for m in meshes), len(materials), len(armature_data))
    if options.import_animation:
        fps = scene.render.fps / scene.render.fps_base
        for a in gfg.animations:
            targets = [objects[a.node]] if a.node >= 0 else \
                [o for n, o in zip(gfg.nodes, objects) if n.kind == NodeKind.ARMATURE and n.skeleton == a.skeleton][:1]
            for target in targets:
                import_animation(target, gfg.skeletons[a.skeleton], a, fps)
                summary.animations += 1
        scene.frame_set(scene.frame_current)  # pose the armatures at the current frame
    session = scene_session(scene.name_full)
    if options.attach_voxel_caches and gfg.voxels is not None:
        result = voxel_set_to_result(gfg.voxels)
        result.caches = {k: [None if c is None else _copied(c) for c in cs] for k, cs in result.caches.items()}
        session.caches = result
        summary.voxel_caches = len(gfg.voxels.caches)
        missing = [name for name in result.bindings if name not in bpy.data.objects]
        if missing:
            warnings.append(f"{len(missing)} voxel-cache bindings name objects not in this file "
                            f"(e.g. '{missing[0]}')")
    if options.attach_probes and gfg.probe_grids:
        from ..probe_store import save_grids  # kept with the .blend like baked ones

        save_grids(scene, [replace(g, **{f: np.array(v) for f, v in vars(g).items()
                                         if isinstance(v, np.ndarray)}) for g in gfg.probe_grids])
        summary.probe_grids = len(gfg.probe_grids)
    return summary

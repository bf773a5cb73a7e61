"""Skeletons, poses and skeletal animation between Blender and GFG files (main thread).

Bones are stored parents first, depth-first with siblings sorted by name, so the order does
not depend on how Blender happens to list them. Head, tail and roll are read in edit mode
(exactly what Blender stores), so an imported armature has bit-identical ``matrix_local``.
Animation keeps what the thesis' runtime plays: per-bone rotations as quaternions (WXYZ)
and the root bone's location ("hip translation"), sampled per frame or at the keys.
"""
from __future__ import annotations

import math

import bpy
import mathutils
import numpy as np
from bpy_extras import anim_utils

from ...voxgi_addon.files.gfg import Animation, Pose, Skeleton
from ...voxgi_addon.files.gfg.spec import BoneFlag, Interpolation, QuatLayout
from ..scene_building import BoneSpec, add_bones, armature_edit_mode

ROTATION_PATHS = {"QUATERNION": ("rotation_quaternion", 4), "AXIS_ANGLE": ("rotation_axis_angle", 4)}
MIN_BONE_LENGTH = 1e-3  # Blender deletes shorter bones when leaving edit mode
KEY_INTERPOLATION = {Interpolation.SLERP: 1, Interpolation.CUBIC: 2}  # LINEAR, BEZIER


def bone_order(armature) -> list:
    """``armature.bones`` parents first, depth-first, siblings by name."""
    ordered, stack = [], sorted((b for b in armature.bones if b.parent is None), key=lambda b: b.name,
                                reverse=True)
    while stack:
        bone = stack.pop()
        ordered.append(bone)
        stack.extend(sorted(bone.children, key=lambda b: b.name, reverse=True))
    return ordered


def _edit_bone_values(scene, view_layer, armature_obj, names, warnings):
    """{name: (head, tail, roll)} read in edit mode, or derived from the rest matrices."""
    try:
        with armature_edit_mode(scene, armature_obj, view_layer) as edit_bones:
            return {n: (tuple(edit_bones[n].head), tuple(edit_bones[n].tail), edit_bones[n].roll)
                    for n in names}
    except RuntimeError:
        warnings.append(f"Armature '{armature_obj.name}' cannot enter edit mode (linked or hidden): "
                        "bone rolls are derived from the rest matrices")
        bones = armature_obj.data.bones
        return {n: (tuple(bones[n].head_local), tuple(bones[n].tail_local),
                    bpy.types.Bone.AxisRollFromMatrix(bones[n].matrix_local.to_3x3())[1]) for n in names}


def export_skeleton(scene, view_layer, armature_obj, warnings) -> Skeleton:
    """The rest pose of an armature object's bones."""
    bones = bone_order(armature_obj.data)
    names = tuple(b.name for b in bones)
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[b.parent.name] if b.parent else -1 for b in bones], np.int32)
    flags = np.array([BoneFlag.DEFORM * b.use_deform + BoneFlag.CONNECTED * b.use_connect for b in bones],
                     np.uint32)
    # Leaving edit mode rebuilds the bones: ``bones`` must not be touched after this line.
    values = _edit_bone_values(scene, view_layer, armature_obj, names, warnings)
    by_name = armature_obj.data.bones
    return Skeleton(
        name=armature_obj.data.name_full, bone_names=names, parents=parents, flags=flags,
        heads=np.array([values[n][0] for n in names], np.float32).reshape(-1, 3),
        tails=np.array([values[n][1] for n in names], np.float32).reshape(-1, 3),
        rolls=np.array([values[n][2] for n in names], np.float32),
        rest_matrices=np.array([by_name[n].matrix_local for n in names], np.float32).reshape(-1, 4, 4),
    )


def import_skeleton(scene, armature_obj, skeleton: Skeleton, warnings) -> None:
    """Create the skeleton's bones in ``armature_obj`` (linked into ``scene``)."""
    specs = []
    for i, name in enumerate(skeleton.bone_names):
        head, tail = np.asarray(skeleton.heads[i], np.float64), np.asarray(skeleton.tails[i], np.float64)
        if np.linalg.norm(tail - head) < MIN_BONE_LENGTH:
            warnings.append(f"Bone '{name}' is shorter than {MIN_BONE_LENGTH} m; lengthened so Blender keeps it")
            tail = head + (0.0, 10 * MIN_BONE_LENGTH, 0.0)
        parent = int(skeleton.parents[i])
        flags = int(skeleton.flags[i])
        specs.append(BoneSpec(name, tuple(head), tuple(tail),
                              skeleton.bone_names[parent] if parent >= 0 else None,
                              bool(flags & BoneFlag.DEFORM), bool(flags & BoneFlag.CONNECTED),
                              float(skeleton.rolls[i])))
    add_bones(scene, armature_obj, specs)


def _quaternion(mode: str, values) -> tuple[float, float, float, float]:
    if mode == "QUATERNION":
        return tuple(values)
    if mode == "AXIS_ANGLE":
        return tuple(mathutils.Quaternion(values[1:], values[0]))
    return tuple(mathutils.Euler(values, mode).to_quaternion())


def _rotation_path(pose_bone) -> tuple[str, int]:
    return ROTATION_PATHS.get(pose_bone.rotation_mode, ("rotation_euler", 3))


def export_pose(armature_eval, skeleton: Skeleton) -> Pose:
    """The current local pose (evaluated: animation applied) in skeleton bone order."""
    bones = [armature_eval.pose.bones[n] for n in skeleton.bone_names]
    rotations = [_quaternion(b.rotation_mode, getattr(b, _rotation_path(b)[0])[:]) for b in bones]
    return Pose(np.array(rotations, np.float32).reshape(-1, 4),
                np.array([b.location[:] for b in bones], np.float32).reshape(-1, 3),
                np.array([b.scale[:] for b in bones], np.float32).reshape(-1, 3))


def apply_pose(armature_obj, skeleton: Skeleton, pose: Pose) -> None:
    for i, name in enumerate(skeleton.bone_names):
        bone = armature_obj.pose.bones[name]
        bone.rotation_mode = "QUATERNION"
        bone.rotation_quaternion = pose.rotations[i].tolist()
        bone.location = pose.locations[i].tolist()
        bone.scale = pose.scales[i].tolist()


def _channel(bag, name: str, prop: str, index: int):
    return bag.fcurves.find(f'pose.bones["{bpy.utils.escape_identifier(name)}"].{prop}', index=index)


def _key_frames(action, channels, sample: bool) -> np.ndarray:
    if sample:
        start, end = action.frame_range
        return np.arange(math.ceil(start), math.floor(end) + 1, dtype=np.float64)
    frames = [k.co[0] for fc in channels for k in fc.keyframe_points]
    return np.unique(np.array(frames, np.float64))


def export_animation(armature_obj, skeleton: Skeleton, skeleton_index: int, node_index: int,
                     fps: float, sample: bool, warnings) -> Animation | None:
    """The armature's active action as a GFG animation, or None without one.

    Channels without an F-curve keep the bone's current value; translation keys of other
    bones than the root, and scale keys, are dropped (with a warning).
    """
    anim = armature_obj.animation_data
    bag = None if anim is None or anim.action is None else \
        anim_utils.animdata_get_channelbag_for_assigned_slot(anim)
    if bag is None:
        return None
    pose_bones = [armature_obj.pose.bones[n] for n in skeleton.bone_names]
    rotation, channels = [], []
    for b, pb in zip(skeleton.bone_names, pose_bones):
        prop, width = _rotation_path(pb)
        curves = [_channel(bag, b, prop, i) for i in range(width)]
        rotation.append((pb.rotation_mode, prop, curves))
        channels += [c for c in curves if c is not None]
    hip_curves = [_channel(bag, skeleton.bone_names[0], "location", i) for i in range(3)] if pose_bones else []
    channels += [c for c in hip_curves if c is not None]
    dropped = [fc.data_path for fc in bag.fcurves if fc.data_path.endswith((".location", ".scale"))
               and fc not in channels]
    if dropped:
        warnings.append(f"Action '{anim.action.name}': only rotations and the root bone's location are "
                        f"exported; dropped {len(dropped)} location/scale channels")
    if not channels:
        return None
    frames = _key_frames(anim.action, channels, sample)

    def evaluate(curves, defaults):
        return [[c.evaluate(f) if c is not None else d for c, d in zip(curves, defaults)] for f in frames]

    keys = np.zeros((len(frames), len(pose_bones), 4), np.float32)
    for b, (pb, (mode, prop, curves)) in enumerate(zip(pose_bones, rotation)):
        for k, values in enumerate(evaluate(curves, getattr(pb, prop)[:])):
            keys[k, b] = _quaternion(mode, values)
    hips = None
    if any(c is not None for c in hip_curves):
        hips = np.array(evaluate(hip_curves, pose_bones[0].location[:]), np.float32).reshape(-1, 3)
    return Animation(anim.action.name, skeleton_index, (frames / fps).astype(np.float32), keys, hips,
                     node=node_index, frame_rate=float(np.float32(fps)))


def _set_keys(curve, frames, values, interpolation: int) -> None:
    curve.keyframe_points.add(len(frames))
    curve.keyframe_points.foreach_set("co", np.column_stack([frames, values]).astype(np.float32).reshape(-1))
    curve.keyframe_points.foreach_set("interpolation", np.full(len(frames), interpolation, np.int32))
    curve.update()


def import_animation(armature_obj, skeleton: Skeleton, animation: Animation, fps: float):
    """A new action on ``armature_obj`` playing ``animation`` (key times → frames at ``fps``)."""
    action = bpy.data.actions.new(animation.name)
    slot = action.slots.new(id_type="OBJECT", name=armature_obj.name)
    anim = armature_obj.animation_data_create()
    anim.action, anim.action_slot = action, slot
    bag = anim_utils.action_ensure_channelbag_for_slot(action, slot)
    frames = np.asarray(animation.times, np.float64) * fps
    nearest = np.rint(frames)
    frames = np.where(np.abs(frames - nearest) < 1e-3, nearest, frames)  # whole frames stay whole
    rotations = np.asarray(animation.rotations, np.float32)
    if animation.quat_layout == QuatLayout.XYZW:
        rotations = rotations[..., [3, 0, 1, 2]]
    interpolation = KEY_INTERPOLATION[animation.interpolation]
    for b, name in enumerate(skeleton.bone_names):
        armature_obj.pose.bones[name].rotation_mode = "QUATERNION"
        path = f'pose.bones["{bpy.utils.escape_identifier(name)}"]'
        for i in range(4):
            _set_keys(bag.fcurves.new(f"{path}.rotation_quaternion", index=i, group_name=name),
                      frames, rotations[:, b, i], interpolation)
        if animation.hip_translations is not None and b == animation.hip_bone:
            for i in range(3):
                _set_keys(bag.fcurves.new(f"{path}.location", index=i, group_name=name),
                          frames, np.asarray(animation.hip_translations)[:, i], interpolation)
    return action

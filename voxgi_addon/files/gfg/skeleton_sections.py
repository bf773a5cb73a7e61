"""SKEL and ANIM sections: bones in their bind pose, skeletal animations."""
from __future__ import annotations

import numpy as np

from . import data_types as dtypes
from .container import SectionBuilder, SectionView
from .errors import GFGError
from .model import Animation, Skeleton
from .scene_sections import StringTable, StringView, check_index
from .spec import (
    ANIMATION_INFO,
    BONE_RECORD,
    SKELETON_INFO,
    AnimLayout,
    AnimType,
    Interpolation,
    Kind,
    NodeKind,
    QuatLayout,
    Role,
)

FLOAT1, FLOAT3 = dtypes.code_of("FLOAT_1"), dtypes.code_of("FLOAT_3")
FLOAT4, QUAT = dtypes.code_of("FLOAT_4"), dtypes.code_of("QUATERNION")


def encode_skeleton(skeleton: Skeleton, strings: StringTable) -> SectionBuilder:
    b = skeleton.bone_count
    records = np.zeros(b, BONE_RECORD)
    records["parent"] = skeleton.parents
    records["name"] = [strings(n) for n in skeleton.bone_names]
    records["flags"] = skeleton.flags
    records["roll"] = skeleton.rolls
    records["head"] = skeleton.heads
    records["tail"] = skeleton.tails
    s = SectionBuilder(Kind.SKELETON, np.array([(strings(skeleton.name), b)], SKELETON_INFO))
    s.add(Role.BONES, dtypes.RECORD, records, element_size=BONE_RECORD.itemsize)
    s.add(Role.REST_MATRICES, FLOAT4, np.asarray(skeleton.rest_matrices, "<f4").reshape(b * 4, 4))
    return s


def decode_skeleton(view: SectionView, strings: StringView) -> Skeleton:
    info = view.info(SKELETON_INFO)
    name = strings.get(info["name"], view, "info.name")
    view.name_as(name)
    count = int(info["bone_count"])
    bones = view.array(Role.BONES, "BONES", (dtypes.RECORD,), count, record=BONE_RECORD)
    rest = view.array(Role.REST_MATRICES, "REST_MATRICES", (FLOAT4,), 4 * count)
    parents = bones["parent"]
    if count and not bool(np.all((parents >= -1) & (parents < np.arange(count)))):
        bad = int(np.argmax(~((parents >= -1) & (parents < np.arange(count)))))
        view.fail(f"bone {bad} parent", f"{int(parents[bad])} is not an earlier bone (parents come first)")
    names = tuple(strings.get(n, view, f"bone {i} name") for i, n in enumerate(bones["name"]))
    return Skeleton(name, names, parents, bones["flags"], bones["head"], bones["tail"], bones["roll"],
                    rest.reshape(count, 4, 4))


def encode_animation(anim: Animation, strings: StringTable) -> SectionBuilder:
    rotations = np.asarray(anim.rotations, "<f4")
    if rotations.ndim != 3 or rotations.shape[2] != 4 or rotations.shape[0] != len(anim.times):
        raise GFGError(f"animation '{anim.name}'", "rotations",
                       f"shape {rotations.shape} is not (keys {len(anim.times)}, bones, 4)")
    keys, bones = rotations.shape[:2]
    kind = AnimType.ONLY_QUATERNION if anim.hip_translations is None else AnimType.WITH_HIP_TRANSLATE
    info = np.array([(strings(anim.name), anim.skeleton, anim.node, keys, bones, anim.layout, kind,
                      anim.interpolation, anim.quat_layout, anim.hip_bone, anim.frame_rate)],
                    ANIMATION_INFO)
    s = SectionBuilder(Kind.ANIMATION, info)
    s.add(Role.KEY_TIMES, FLOAT1, np.asarray(anim.times, "<f4"))
    if anim.hip_translations is not None:
        s.add(Role.HIP_TRANSLATIONS, FLOAT3, np.asarray(anim.hip_translations, "<f4").reshape(keys, 3))
    stored = rotations if anim.layout == AnimLayout.BONES_OF_KEYS else rotations.transpose(1, 0, 2)
    s.add(Role.ROTATIONS, QUAT, stored)
    return s


def decode_animation(view: SectionView, strings: StringView, bone_counts: list[int],
                     node_kinds: list[tuple[int, int]]) -> Animation:
    """node_kinds : (kind, skeleton) of every node, to check the target node."""
    info = view.info(ANIMATION_INFO)
    name = strings.get(info["name"], view, "info.name")
    view.name_as(name)
    skeleton = check_index(view, "info.skeleton", info["skeleton"], len(bone_counts))
    keys, bones = int(info["key_count"]), int(info["bone_count"])
    if bones != bone_counts[skeleton]:
        view.fail("info.bone_count", f"{bones} but skeleton {skeleton} has {bone_counts[skeleton]} bones")
    node = int(info["node"])
    if node != -1 and (not 0 <= node < len(node_kinds) or node_kinds[node] != (NodeKind.ARMATURE, skeleton)):
        view.fail("info.node", f"{node} is not an ARMATURE node of skeleton {skeleton}")
    layout, kind = int(info["layout"]), int(info["type"])
    interpolation, quat_layout = int(info["interpolation"]), int(info["quat_layout"])
    for field, value, allowed in (("layout", layout, (AnimLayout.KEYS_OF_BONES, AnimLayout.BONES_OF_KEYS)),
                                  ("type", kind, (AnimType.WITH_HIP_TRANSLATE, AnimType.ONLY_QUATERNION)),
                                  ("interpolation", interpolation, (Interpolation.SLERP, Interpolation.CUBIC)),
                                  ("quat_layout", quat_layout, (QuatLayout.WXYZ, QuatLayout.XYZW))):
        if value not in allowed:
            view.fail(f"info.{field}", f"{value} is not one of {allowed}")
    hip_bone = int(info["hip_bone"])
    if bones and hip_bone >= bones:
        view.fail("info.hip_bone", f"{hip_bone} is not one of the {bones} bones")
    times = view.array(Role.KEY_TIMES, "KEY_TIMES", (FLOAT1,), keys)
    if keys > 1 and not bool(np.all(times[1:] >= times[:-1])):
        view.fail("array KEY_TIMES", "key times decrease")
    hips = None
    if kind == AnimType.WITH_HIP_TRANSLATE:
        hips = view.array(Role.HIP_TRANSLATIONS, "HIP_TRANSLATIONS", (FLOAT3,), keys)
    rot = view.array(Role.ROTATIONS, "ROTATIONS", (QUAT, FLOAT4), keys * bones)
    if layout == AnimLayout.BONES_OF_KEYS:
        rotations = rot.reshape(keys, bones, 4)
    else:
        rotations = rot.reshape(bones, keys, 4).transpose(1, 0, 2)
    return Animation(name, skeleton, times, rotations, hips, hip_bone, node, float(info["frame_rate"]),
                     interpolation, layout, quat_layout)

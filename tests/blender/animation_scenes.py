"""An animated scene for F12 animation renders (the tests and ``make bench``'s animation section):
the skinned figure of ``gi_scenes`` walking."""
from __future__ import annotations

import math

import bpy
import gi_scenes
import numpy as np

FRAMES = 12


def walking_rig(scene):
    """The skinned figure walking: its rig moves 1.2 m along X over 12 frames while its bones
    swing back and forth (keyframed), the rest of the scene still."""
    gi_scenes.build("skinned_figure", scene)
    rig = bpy.data.objects["Figure Rig"]
    start = rig.location.x
    for frame in (1, FRAMES):
        rig.location.x = start + 1.2 * (frame - 1) / (FRAMES - 1)
        rig.keyframe_insert("location", frame=frame)
    for frame in range(1, FRAMES + 1, 3):
        swing = 0.35 * math.sin(frame * 0.9)
        for bone in rig.pose.bones[1:]:
            bone.rotation_euler = (-0.15 + swing, 0.0, 0.3 - swing)
            bone.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_start, scene.frame_end = 1, FRAMES
    return rig


def mean_change(frames, still):
    """Mean |frame k+1 − frame k| of Combined over the ``still`` pixels, all frame pairs."""
    return float(np.mean([np.abs(b[still] - a[still]).mean() for a, b in zip(frames, frames[1:])]))

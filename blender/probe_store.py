"""A scene's baked probe grids: kept with the .blend, cached in the session, progress of a bake
(docs/probes.md "Persistence").

The grids live in a Text datablock ``.voxgi_probes.<scene>`` as ``voxgi_addon.probes.store``
text (a zlib-compressed GFG file in base64: compact, every byte checked when read back); it is
saved with the .blend like any datablock, and nothing big goes into ID properties. The session
holds the decoded grids (``SceneSession.probes``) so drawing and queries do not decode again;
loading a file clears the session and the next use decodes the text.
"""
from __future__ import annotations

import threading

import bpy
import numpy as np

from ..voxgi_addon.files.gfg import GFGError
from ..voxgi_addon.probes.store import from_text, to_text
from .session import peek_session, scene_session

TEXT_PREFIX = ".voxgi_probes."
_progress: dict[str, float] = {}
_lock = threading.Lock()


def text_name(scene_name: str) -> str:
    return TEXT_PREFIX + scene_name


def save_grids(scene, grids) -> None:
    """Keep ``grids`` for ``scene``: in its session and in the Text datablock (main thread)."""
    name = text_name(scene.name_full)
    text = bpy.data.texts.get(name) or bpy.data.texts.new(name)
    text.from_string(to_text(grids))
    text.use_fake_user = True  # nothing links to it: keep it on save
    scene_session(scene.name_full).probes = list(grids)


def clear_grids(scene) -> None:
    text = bpy.data.texts.get(text_name(scene.name_full))
    if text is not None:
        bpy.data.texts.remove(text)
    session = peek_session(scene.name_full)
    if session is not None:
        session.probes = None


def load_grids(scene) -> list:
    """The scene's grids (session first, else decoded from its Text datablock); [] when none or
    when the stored text is damaged (then a warning is printed once and the text is left)."""
    session = peek_session(scene.name_full)
    if session is not None and session.probes:
        return session.probes
    text = bpy.data.texts.get(text_name(scene.name_full))
    if text is None:
        return []
    try:
        grids = from_text(text.as_string())
    except GFGError as error:
        print(f"VoxGI: the stored probes of scene '{scene.name_full}' cannot be read: {error}")
        grids = []
    scene_session(scene.name_full).probes = grids
    return grids


def probe_volume_boxes(scene, depsgraph=None) -> list[tuple[str, np.ndarray, np.ndarray, tuple]]:
    """(name, lo, hi, dims) of each visible Light Probe Volume object: the world bounds of its
    box (the object's ±1 cube; a rotated box gives its axis-aligned bounds) and its resolution."""
    boxes = []
    objects = depsgraph.objects if depsgraph is not None else scene.objects
    for obj in objects:
        data = getattr(obj, "data", None)
        if obj.type != "LIGHT_PROBE" or getattr(data, "type", "") != "VOLUME":
            continue
        if depsgraph is None and not obj.visible_get():
            continue
        m = np.array(obj.matrix_world, np.float64)
        corners = np.array([[x, y, z, 1.0] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        world = (corners @ m.T)[:, :3]
        dims = (data.resolution_x, data.resolution_y, data.resolution_z)
        boxes.append((obj.name, world.min(axis=0), world.max(axis=0), tuple(int(d) for d in dims)))
    return boxes


def set_progress(scene_name: str, share: float | None) -> None:
    """Called from the worker thread (plain Python, no bpy)."""
    with _lock:
        if share is None:
            _progress.pop(scene_name, None)
        else:
            _progress[scene_name] = float(share)


def progress(scene_name: str) -> float | None:
    with _lock:
        return _progress.get(scene_name)


classes = ()

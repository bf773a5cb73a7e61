"""Reading a Blender scene into the engine's ``SceneSnapshot`` (main thread only).

``scene.take_snapshot`` is the entry; ``mesh``, ``skin``, ``materials`` and ``environment``
read one kind of datablock each with ``foreach_get``.
"""
from __future__ import annotations

import time

from ...voxgi_addon.errors import VoxGIError
from .scene import snapshot_summary, take_snapshot

__all__ = ["NO_MESH_MESSAGE", "snapshot_or_error", "snapshot_summary", "take_snapshot"]

NO_MESH_MESSAGE = (
    "Nothing to voxelize: the view layer has no visible mesh object with faces "
    "(add one, or unhide it)"
)

def snapshot_or_error(context, depsgraph=None):
    """(snapshot, seconds) of the context's scene (or of ``depsgraph``'s scene and view layer);
    VoxGIError when it has nothing to voxelize."""
    start = time.perf_counter()
    if depsgraph is None:
        snapshot = take_snapshot(context, context.evaluated_depsgraph_get())
    else:
        snapshot = take_snapshot(depsgraph.scene_eval.original, depsgraph)
    seconds = time.perf_counter() - start
    if not snapshot.objects:
        details = "; ".join(snapshot.warnings)
        raise VoxGIError(NO_MESH_MESSAGE + (f". {details}" if details else ""))
    return snapshot, seconds

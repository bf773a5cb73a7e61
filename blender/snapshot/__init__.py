"""Reading a Blender scene into the engine's ``SceneSnapshot`` (main thread only).

``scene.take_snapshot`` is the entry; ``mesh``, ``skin``, ``materials`` and ``environment``
read one kind of datablock each with ``foreach_get``; ``pose.posed_snapshot`` re-reads only what
a pose or a move changes (docs/gi_pipeline.md "Posed updates"), ``reads`` counts what was read.
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

def snapshot_or_error(context, depsgraph=None, posed: bool = False, reads=None,
                      allow_empty: bool = False, bakes=None):
    """(snapshot, seconds) of the context's scene (or of ``depsgraph``'s scene and view layer);
    VoxGIError when it has nothing to voxelize (unless ``allow_empty``: a render's view layer
    that shows no mesh, whose image is the world alone).

    posed : when only matrices, poses, lights, camera or world changed since the last snapshot
        of this view layer, that snapshot posed at this frame (``updates.posed_since``: no
        mesh evaluated, no material read; docs/gi_pipeline.md "Posed updates"); a full
        snapshot otherwise.
    reads : the live viewport's kept mesh reads (``mesh_cache.MeshReads``, ``take_snapshot``).
    bakes : the live viewport's queue of material bakes (``bakes.BakeQueue``, ``take_snapshot``).
    """
    from ..updates import posed_since, remember  # updates reads snapshots: imported late

    start = time.perf_counter()
    if depsgraph is None:
        depsgraph = context.evaluated_depsgraph_get()  # evaluates (and logs) pending changes
        scene = context.scene
    else:
        scene = depsgraph.scene_eval.original
    snapshot = posed_since(scene, depsgraph) if posed else None
    if snapshot is None:
        snapshot = take_snapshot(scene, depsgraph, reads, bakes)
    if snapshot.objects:
        remember(snapshot, scene, depsgraph)
    seconds = time.perf_counter() - start
    if not snapshot.objects and not allow_empty:
        details = "; ".join(snapshot.warnings)
        raise VoxGIError(NO_MESH_MESSAGE + (f". {details}" if details else ""))
    return snapshot, seconds

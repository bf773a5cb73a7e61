"""Fast quality's voxels with the radiance cache's bounces, ready for the GPU as one value.

At Bounces > 1 Fast's cones read octrees rebuilt from the update's voxels plus what the
radiance cache reflects at them (``gi.cone_bounces.cone_octrees``; docs/gi_pipeline.md "Fast
quality's cones"), and the GPU samples each octree through its atlas layout
(``volume_textures.volume_atlas``). Both are numpy on engine data only — 0.4 s and more on
the Cornell box — so the live viewport has its worker thread make them
(``blender/viewport_session.py``) and the main thread only uploads the atlas
(``render/gpu_fast.py``): ``BouncedVolumes`` is what the worker hands over.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..gi.cone_bounces import cone_octrees
from ..gi.ray_views import KINDS, view_octree
from .volume_textures import volume_atlas

__all__ = ["BouncedVolumes", "bounced_volumes", "update_octrees"]


def update_octrees(state) -> tuple:
    """The update's own octree of each kind of cone (``ray_views.view_octree``): what the
    rebuilt ones are made from (an update that reused everything is a new state holding
    the same octrees)."""
    return tuple(view_octree(state, kind) for kind in KINDS)


@dataclass(frozen=True, eq=False)
class BouncedVolumes:
    """The octree of each kind of cone (``ray_views.KINDS``) rebuilt with ``cache``'s bounces
    from the update octrees ``made_from``, and the atlas of each (by ``id`` of the octree)."""

    made_from: tuple
    cache: object
    octrees: dict
    atlases: dict

    def fits(self, state, cache=None) -> bool:
        """Built from ``state``'s octrees (and, when given, for ``cache``): the same objects."""
        own = update_octrees(state)
        same = len(own) == len(self.made_from) and all(
            a is b for a, b in zip(own, self.made_from))
        return same and (cache is None or cache is self.cache)

    def atlas(self, octree):
        """The atlas of one of ``octrees`` (None for another octree)."""
        return self.atlases.get(id(octree))


def bounced_volumes(state, cache) -> BouncedVolumes:
    """``BouncedVolumes`` of the update ``state`` (``update.GIState``) with the radiance
    ``cache`` (a ``RadianceCache``): ``cone_octrees`` and each distinct octree's
    ``volume_atlas``. No bpy, no GPU: a worker thread may run it."""
    if cache is None:
        raise ValueError("bounced volumes need a radiance cache (one bounce reads the "
                         "update's own octrees)")
    octrees = cone_octrees(state, cache)
    atlases = {}
    for octree in octrees.values():
        if id(octree) not in atlases:
            atlases[id(octree)] = volume_atlas(octree)
    return BouncedVolumes(update_octrees(state), cache, dict(octrees), atlases)

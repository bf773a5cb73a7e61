"""The viewport's radiance cache, built a few voxel faces at a time between its slices.

F12 and ``render_preview`` build the multi-bounce radiance cache whole before their gathers
(``gpu_gather.cache_texture``: every iteration's gather over all voxel faces, seconds on
llvmpipe). Inside ``view_draw`` that froze Blender for the whole build on every object move
(12 s in the viewport benchmark under load). Here the same build (``cache_gpu``'s layout,
rays and sample ids) runs as a generator of stages — one chunk of face rows of one
iteration per stage (the other rows masked, so every face keeps the sample id, and the
result is the whole build's) — sized to the slice's stage budget from the last chunk's
time. Until it completes the gathers read the last complete cache (bounces that lag an edit,
as the live engines' caches do), or none (one bounce) before the first; a completed build
bumps ``generation``, which is part of the viewport's image key, so the image restarts with
the new cache — which is why, once a slice of Accurate's image has asked for a build, the
viewport runs its chunks ahead of the tiles (``advance_first``: tiles traced meanwhile would
be dropped). The build's CPU half — the cache's voxels, face points and layout
(``gpu_gather.cache_layout``, 0.15 s of numpy on the demo box, more on larger scenes) — is
made on the viewport's preparing thread first (``viewport_prepare.PrepWorker``), never in a
draw (docs/gi_pipeline.md "Entering Rendered mode").

A complete build is the session's too (``gpu_gather.share_cache``), and a view whose scene the
session already holds a complete cache for takes it instead of building one
(``gpu_gather.shared_cache``): a view entered after F12, or switched off and on again, starts
on every bounce at once, and F12 after a view builds none (docs/gi_pipeline.md "One radiance
cache for F12 and the Rendered view").
"""
from __future__ import annotations

from ..voxgi_addon.gi.radiance_cache import cache_key
from ..voxgi_addon.preview.gather import cache_settings, uses_cache
from .gpu_gather import CACHE_STAGE_SECONDS, cache_layout, cache_stages, share_cache, shared_cache

STAGE_SECONDS = CACHE_STAGE_SECONDS  # what one chunk aims at (half the 30 ms budget)


class ViewportCache:
    """One view's radiance cache: the last complete one, the build under way, a generation
    that counts completed builds (``module doc``)."""

    def __init__(self, budget: float = STAGE_SECONDS):
        self.budget = budget
        self.texture = None    # the last complete cache's texture
        self._read = None      # ... a function reading its RadianceCache back (``cache``)
        self._cache = None
        self.key = None        # what it was built for
        self.building = None   # (key, generator) of the build under way; generator None
        #                        while the worker makes its layout (``layout``)
        self.layout = None     # (tris, cache settings, holder) of the layout asked for
        self._inputs = None    # the build's arguments (``stage``)
        self.generation = 0
        self._wanted = None    # (key, arguments) of a build a held stage asked for
        # set by the viewport while it traces a coarse first image: a new build does not start
        # (nor go on) in it, so the image of a change is not held up by the build's first
        # chunk (its layout alone 0.3 s); the tiles after it start the build
        self.hold = False
        # the viewport's image key while its slices run (set before each), and the one whose
        # slice last asked for the build under way: ``advance_first`` runs only that build
        self.image_key = None
        self.asked = None

    def stage(self, bvh, lights, principled, emission, settings, tables=None):
        """A generator of at most one stage (one chunk of the build the current scene needs),
        returning the cache texture the gathers read now — the complete one for the current
        scene, else the last complete one — or None when there is none yet (one bounce)."""
        if not uses_cache(settings):
            return None
        # the BVH's node texture is replaced whenever other triangles are uploaded
        key = (bvh.nodes, cache_key(lights, principled, emission, *cache_settings(settings)))
        if _same(key, self.key):
            return self.texture
        if self._adopt(key):  # F12 or another view built it: no stage (even while held)
            return self.texture
        if self.hold:  # asked for, not begun: ``resume`` begins it if the image converges first
            self._wanted = (key, (bvh, lights, principled, emission, settings, tables))
            return self.texture
        self._wanted = None
        self.asked = self.image_key
        if self.building is None or not _same(self.building[0], key):
            if self.building is not None and self.building[1] is not None:
                self.building[1].close()
            self.building = (key, None)
            self._inputs = (bvh, lights, principled, emission, settings, tables)
        if self.building[1] is None and not self._start():
            return self.texture  # its layout is being made: no stage yet
        if self.advance():
            return self.texture
        yield
        return self.texture

    def _start(self) -> bool:
        """Start the build under way once its layout is made (asked for here, on the
        viewport's preparing thread; at once in background mode); whether it started."""
        bvh, lights, principled, emission, settings, tables = self._inputs
        tris, wanted = bvh.scene_triangles, cache_settings(settings)
        if self.layout is None or self.layout[0] is not tris or self.layout[1] != wanted:
            from .viewport_prepare import worker

            holder = {}
            self.layout = (tris, wanted, holder)

            def make():  # the viewport's preparing thread: numpy only
                try:
                    holder["layout"] = cache_layout(tris, settings)
                except Exception as error:  # noqa: BLE001 - raised by the next draw's stage
                    holder["error"] = error

            worker.submit(f"radiance cache {id(self)}", make)
        if "error" in self.layout[2]:
            error, self.layout = self.layout[2]["error"], None
            raise error
        layout = self.layout[2].get("layout")
        if layout is None:
            return False
        key = self.building[0]
        self.building = (key, cache_stages(bvh, lights, principled, emission, settings, tables,
                                           self.budget, read_back=False, layout=layout))
        return True

    def resume(self) -> bool:
        """Begin the build a held ``stage`` asked for, when none is under way (the image
        converged before any unheld stage ran: without this it kept one bounce for good);
        whether a build is under way now."""
        if self.building is None and self._wanted is not None and not self.hold:
            key, inputs = self._wanted
            self._wanted = None
            if not _same(key, self.key):
                self.building, self._inputs = (key, None), inputs
        return self.building is not None

    def advance(self) -> bool:
        """Run one chunk of the build under way (if any); True when it completed the cache.
        The viewport calls this on its own while the image has converged on the old cache."""
        if self.building is None:
            return False
        if self.building[1] is None and not self._start():
            return False  # its layout is still being made
        key, stages = self.building
        try:
            next(stages)
        except StopIteration as end:
            (self._read, self.texture), self._cache = end.value, None
            self.key, self.building = key, None
            self.generation += 1
            share_cache(*key, self._read, self.texture)  # for F12 and the next view
            return True
        except BaseException:
            self.building = None
            raise
        return False

    def advance_any(self) -> bool:
        """``advance`` the build under way, whichever image asked for it: whether a chunk ran
        (False: no build under way, or its layout is still being made)."""
        if self.building is None or (self.building[1] is None and not self._start()):
            return False
        self.advance()
        return True

    def advance_first(self, image_key) -> bool:
        """``advance`` the build under way ahead of the tiles of the image ``image_key``:
        whether a chunk ran — False when no slice of that image asked for this build (the
        scene may have changed since: the image's next slice says what it needs) or while its
        layout is being made (the tiles go on meanwhile)."""
        if self.building is None or self.asked is None or self.asked != image_key or \
                (self.building[1] is None and not self._start()):
            return False
        self.advance()
        return True

    def _adopt(self, key) -> bool:
        """Take the session's complete cache for ``key`` (``gpu_gather.shared_cache``) as this
        view's, dropping a build under way; whether there was one. A new generation, as a
        completed build's: the image restarts on it."""
        shared = shared_cache(*key)
        if shared is None:
            return False
        if self.building is not None and self.building[1] is not None:
            self.building[1].close()
        cache, self.texture = shared
        self._read, self._cache = (cache, None) if callable(cache) else (None, cache)
        self.key, self.building, self._wanted = key, None, None
        self.generation += 1
        return True

    @property
    def cache(self):
        """The last complete cache as a ``RadianceCache`` (Fast's voxels reflect it): its
        faces read back from the texture the first time it is asked for — Accurate's gathers
        read the texture only, so its view reads nothing back."""
        if self._cache is None and self._read is not None:
            self._cache = self._read()
        return self._cache

    def free(self) -> None:
        if self.building is not None and self.building[1] is not None:
            self.building[1].close()
        self.__init__(self.budget)


def _same(a, b) -> bool:
    """Keys (node texture, cache_key) equal: the same texture object and the same key."""
    return a is not None and b is not None and a[0] is b[0] and a[1] == b[1]

"""Fast quality's bounces in the 3D view: the voxels rebuilt with the radiance cache on the
engine worker, never inside ``view_draw``.

At Bounces > 1 Fast's cones read octrees rebuilt from the update's voxels and the view's
last complete radiance cache (``viewport_cache.py``), laid out as atlases
(``voxgi_addon/preview/bounced_volumes.py``): 0.4 s of numpy and more on the Cornell box.
The draw after a cache completed used to make them itself. Now ``ViewportBounces.current``,
asked on every draw, gives the ``BouncedVolumes`` the image reflects:

* the ones made for the applied update and the latest cache;
* else it submits their making to the worker (``jobs``, a job of its own beside the scene's
  update jobs) and, meanwhile, keeps the ones it has where they were made for the same update
  (an older cache: the bounces lag a moment, as the cache's do) — the image stays as it is;
* a new update comes with its own when the view had a cache as the job was submitted
  (``LiveGI.bounce_cache``: the session's job makes them beside the octree); otherwise, until
  the worker is done, one bounce (None), so no moved geometry is drawn from old voxels.

``version`` counts what ``current`` gave: it is part of the image key, so the image restarts
when the bounced voxels it reflects change — not when a cache completes before them.
"""
from __future__ import annotations

from ..blender import jobs
from ..blender.redraw import tag_3d_views
from ..voxgi_addon.preview.bounced_volumes import bounced_volumes

JOB_LABEL = "Fast bounces in the voxels"


class ViewportBounces:
    """One view's ``BouncedVolumes`` and the worker job making the next (module doc)."""

    def __init__(self):
        self.shown = None      # what ``current`` gave last
        self.version = 0       # bumped whenever that changes (the image key)
        self.made = None       # the last BouncedVolumes the worker made for this view
        self.job = None        # the job making them, while it runs
        self.job_for = None    # (update state, cache) it makes them for
        self.job_key = ""      # its jobs' scene key (``jobs.submit``)

    @property
    def pending(self) -> bool:
        return self.job is not None and self.job.state == "running"

    def current(self, live, cache):
        """The ``BouncedVolumes`` for ``live``'s applied update and the radiance ``cache``
        (``RadianceCache``, the view's last complete one; None: none yet, one bounce), or
        None (one bounce); submits their making when they are missing. Main thread."""
        live.bounce_cache = cache  # the session's next update job makes them with it
        state = None if live.staged is None else live.staged.state
        if cache is None or state is None:
            return self._give(None)
        for made in (self.shown, self.made, live.bounced):
            if made is not None and made.fits(state, cache):
                return self._give(made)
        if not (self.pending and self.job_for[0] is state and self.job_for[1] is cache):
            self._submit(live.scene_name, state, cache)
            if self.made is not None and self.made.fits(state, cache):
                return self._give(self.made)  # a synchronous job (background mode): done
        # meanwhile: the ones of the same update with an older cache, else one bounce
        for made in (self.shown, live.bounced, self.made):
            if made is not None and made.fits(state):
                return self._give(made)
        return self._give(None)

    def _give(self, made):
        if made is not self.shown:
            self.shown = made
            self.version += 1
        return made

    def _submit(self, scene_name: str, state, cache) -> None:
        def job(cancel):  # worker thread: numpy on engine data only
            return bounced_volumes(state, cache)

        def done(made):
            self.made = made
            tag_3d_views()  # the view picks them up on its next draw

        self.job_for = (state, cache)
        self.job_key = f"{scene_name} · bounced voxels"
        self.job = jobs.submit(self.job_key, job, label=JOB_LABEL, on_done=done)

    def free(self) -> None:
        if self.pending:
            jobs.cancel(self.job_key, discard=True)
        self.__init__()


class FastCacheSource:
    """``gpu_preview.render_passes_stages``' cache_source for Fast quality's slices: the
    view's ``ViewportCache`` builds on (a chunk per stage, as for Accurate), and the voxels
    reflect ``cache`` — the ``BouncedVolumes`` ``ViewportBounces.current`` gave (None: one
    bounce) — so no slice rebuilds an octree."""

    def __init__(self, view_cache, bounced):
        self.view_cache, self.cache = view_cache, bounced

    def stage(self, *args, **kwargs):
        yield from self.view_cache.stage(*args, **kwargs)
        return self.cache

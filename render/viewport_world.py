"""The Rendered view of a view layer that shows no mesh: its world alone, as Cycles' view.

F12 renders such a layer's world alone (``render/pipeline.py`` ``empty_passes`` through the
film); the view does the same. ``LiveGI`` keeps the layer's snapshot (``world_only``) instead of
reporting "Nothing to voxelize", and ``WorldView`` draws the film's background
(``preview.film``: the world along the camera rays, through Cycles' pixel filter). The
world is looked up on the preparing thread (``viewport_prepare.worker``; numpy, 0.1–4 s at a
view's size), first at the pixel centres, then through the filter, each image drawn when it is
there; a new view, world or film cancels the lookups under way. With Film › Transparent the
view shows its own background, as Cycles' does; a black world is black.
"""
from __future__ import annotations

import threading

import numpy as np

from ..voxgi_addon.preview.film import background, world_along
from ..voxgi_addon.scene.view_camera import camera_from_view
from . import viewport_prepare


class WorldView:
    """One view's world-alone image: the lookups for its key and the images they gave."""

    def __init__(self):
        self.key = None
        self.done = False      # the filtered image of this key is the one shown
        self._lock = threading.Lock()
        self._generation = 0
        self._ready: list[tuple[int, np.ndarray, bool]] = []  # (generation, RGB, filtered)

    def step(self, renderer, snapshot, view, window, width: int, height: int, camera_key,
             transparent: bool, filter_width: float, redraw=None) -> None:
        """A draw's part: start the lookups of a new key, show what they gave since (an RGB
        image the worker made, uploaded as the renderer's texture), and ask for a redraw
        while the filtered image is still to come."""
        world = snapshot.world
        radiance = getattr(world, "radiance", None)
        key = (id(snapshot), camera_key, transparent, filter_width)
        if key != self.key:
            with self._lock:
                self._generation += 1
                self._ready.clear()
            self.key, self.done = key, False
            if transparent or radiance is None:  # nothing behind the view, or a black world
                renderer.upload(np.zeros((1, 1, 4 if transparent else 3), np.float32))
                self.done = True
                return
            self._submit(world, camera_from_view(view, window, width, height), width, height,
                         filter_width)
        with self._lock:
            ready = [r for r in self._ready if r[0] == self._generation]
            self._ready.clear()
        if ready:
            _, image, filtered = ready[-1]
            renderer.upload(image)
            self.done = filtered
        if not self.done and redraw is not None:
            viewport_prepare.wake_later(redraw)

    def cancel(self) -> None:
        """The layer shows meshes again: the lookups under way stop at their next offset, so
        that the preparing thread turns to the new snapshot's scene."""
        if self.key is not None:
            with self._lock:
                self._generation += 1
                self._ready.clear()
            self.key = None

    def _submit(self, world, camera, width, height, filter_width) -> None:
        generation = self._generation

        def cancelled():
            return generation != self._generation

        def hand(image, filtered):
            with self._lock:
                if not cancelled():
                    self._ready.append((generation, np.asarray(image, np.float32), filtered))

        def task():  # the preparing thread: numpy on the snapshot's plain data
            if cancelled():
                return
            hand(world_along(world, camera, width, height), False)
            image = background(world, camera, width, height, filter_width, cancel=cancelled)
            if image is not None:
                hand(image, True)

        viewport_prepare.worker.submit("world alone", task)

"""Node-built worlds baked in another process for the live viewport (docs/gi_pipeline.md
"World bakes in another process").

A world VoxGI cannot read from its nodes (a Sky Texture, a Noise, a Gradient, a mix…) is
rendered by Cycles as a panorama (``world_map.bake_world``): 0.05–1.4 s on this machine's two
cores, of which a Sky Texture's precomputation alone is about 0.7 s whatever the map's size.
F12 waits for its image anyway and bakes the world itself; the Rendered view must not hold
Blender's main thread that long, and one Cycles render cannot be split into slices.

So the viewport's snapshots ask here (``WorldBakes.want``): the world is written to a temporary
.blend (``bpy.data.libraries.write``, its images by absolute paths; a few milliseconds), and a
child (``blender.child_process``, at the lowest priority) loads it and bakes it with the same
``bake_world``, saving the map beside it. The viewport's timer polls the children
(``WorldBakes.poll``: nothing waits); a finished map goes into ``world_map`` 's cache, and the
viewport reads the world again. Meanwhile the view shows the world's last map in this session
(the state before an edit) or its Background's Color × Strength. A newer edit of the same world
stops the child of the older one.

A world that reads what a child cannot see — an object's place (Texture Coordinate › Object), an
image that lives only in memory — is baked in the snapshot as before (``deferrable``).
"""
from __future__ import annotations

import dataclasses
import os
import shutil
import threading
import time

import numpy as np

from .world_map import world_objects

WORLD_FILE, MAP_FILE, VALUES_FILE = "world.blend", "map.npy", "values.json"


def deferrable(world) -> bool:
    """Whether a child can bake ``world`` as this session would: it reads no object and no
    image whose pixels are only in this session's memory (generated, edited, unsaved)."""
    from ..child_process import sees_images

    return not world_objects(world) and sees_images(world.node_tree)


@dataclasses.dataclass
class _WorldChild:
    """One world's bake in a child process."""

    key: str
    world: str        # the world's name_full
    uses_light_path: bool
    child: object     # child_process.Child


@dataclasses.dataclass
class WorldBakes:
    """The live viewport's world bakes in children (module doc): ``running`` by the world's
    content key; ``finished`` the worlds whose children ended since the viewport last read
    them; ``failed`` why a child brought no map (the next snapshot bakes that world itself)."""

    running: dict[str, _WorldChild] = dataclasses.field(default_factory=dict)
    finished: set[str] = dataclasses.field(default_factory=set)
    failed: dict[str, str] = dataclasses.field(default_factory=dict)
    # (``ahead`` is polled by the UI's timer and waited for by F12's render thread)
    lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, repr=False)

    @property
    def pending(self) -> int:
        return len(self.running)

    def want(self, world, key: str, height: int, uses_light_path: bool,
             values: list | None = None, frame: int = 1) -> None:
        """Bake ``world`` (content key ``key``; ``values``: its animated paths' values at a
        render's frame, ``animated.frame_values``) in a child unless one bakes it already; a
        child baking an older state of the same world is stopped."""
        if key in self.running:
            return
        for older in [k for k, c in self.running.items() if c.world == world.name_full]:
            self._stop(older)
        self.running[key] = _start(world, key, height, uses_light_path, values, frame)

    def wait(self, key: str, seconds: float, store) -> bool:
        """Wait up to ``seconds`` for the child baking ``key`` (any thread: F12's render job
        in the UI, which cannot bake; a cancelled render stops waiting:
        ``bakes.RenderBakes.watching``); whether there was one and its map was stored."""
        from .bakes import render_bakes  # (bakes holds WorldBakes)

        started = time.monotonic()
        while True:
            with self.lock:
                if key not in self.running:
                    return False
                self.poll(store)
                if key not in self.running:
                    return key not in self.failed
            if time.monotonic() - started > seconds or render_bakes.cancelled():
                return False
            time.sleep(0.02)

    def poll(self, store) -> bool:
        """Collect the children that ended: each map handed to ``store(key, radiance,
        uses_light_path, world name)`` (``world_map.store``), or why there is none kept in
        ``failed``; their worlds put in ``finished``. Whether any ended."""
        ended = False
        for key, baking in list(self.running.items()):
            code = baking.child.ended()
            if code is None:
                continue
            ended = True
            del self.running[key]
            try:
                path = baking.child.path(MAP_FILE)
                if code != 0 or not os.path.exists(path):
                    self.failed[key] = f"the background bake ended with code {code}: " \
                        f"{baking.child.tail()}"
                else:
                    try:
                        store(key, np.load(path), baking.uses_light_path, baking.world)
                    except Exception as error:  # noqa: BLE001 - an unreadable map: baked here
                        self.failed[key] = f"its map could not be read ({error})"
                self.finished.add(baking.world)  # read again: its map, or baked there
            finally:
                baking.child.stop()
        return ended

    def stop(self) -> None:
        for key in list(self.running):
            self._stop(key)

    def clear(self) -> None:
        self.stop()
        self.finished.clear()
        self.failed.clear()

    def _stop(self, key: str) -> None:
        self.running.pop(key).child.stop()


ahead = WorldBakes()  # the open file's world, baked before an F12 in the UI needs it


def bake_ahead(scene) -> bool:
    """While a file whose engine is VoxGI is open in Blender's UI (``kernel_warmup``'s timer,
    main thread): start a child for ``scene`` 's world when Cycles must evaluate it and its
    map is not cached, and collect what ended. F12 in the UI renders on a job thread, where no
    bake can run: it waits for this child's map (``world_map.read_world``) instead of
    lighting the scene with the Background's colour. Whether a child started."""
    from .world_map import bake_height, cached, needs_bake, store, uses_light_path, world_key

    with ahead.lock:
        ahead.poll(store)
        ahead.finished.clear()
        world = getattr(scene, "world", None)
        if world is None or not needs_bake(world):
            return False
        key = world_key(world, scene.frame_current)
        if cached(key) or key in ahead.running or key in ahead.failed or not deferrable(world):
            return False
        try:
            ahead.want(world, key, bake_height(world.node_tree), uses_light_path(world.node_tree),
                       frame=scene.frame_current)
        except Exception as error:  # noqa: BLE001 - no child here: F12 says why it cannot bake
            ahead.failed[key] = str(error) or type(error).__name__
            return False
        return True


def _start(world, key: str, height: int, uses_light_path: bool,
           values: list | None = None, frame: int = 1) -> _WorldChild:
    """Write ``world`` (and ``values``, its animated paths' values to bake it with) to a
    temporary directory and start its child (module doc)."""
    import json

    import bpy

    from ..child_process import Child, workspace

    directory = workspace("voxgi-world-child-")
    blend = os.path.join(directory, WORLD_FILE)
    try:
        with open(os.path.join(directory, VALUES_FILE), "w", encoding="utf-8") as out:
            json.dump(list(values or ()), out)
        # (the user's world: the viewport's depsgraph's values are the user's own)
        bpy.data.libraries.write(blend, {getattr(world, "original", None) or world},
                                 path_remap="ABSOLUTE", compress=False)
    except BaseException:
        shutil.rmtree(directory, ignore_errors=True)
        raise
    child = Child.start("blender.snapshot.world_process",
                        [blend, world.name, os.path.join(directory, MAP_FILE), int(height),
                         int(frame)],
                        directory)
    return _WorldChild(key, world.name_full, uses_light_path, child)


def child_main(args: list[str]) -> int:
    """A child (``blender.child_process``): ``BLEND WORLD OUT HEIGHT``: bake the world named
    ``WORLD`` of ``BLEND`` (``world_map.bake_world``) and save its map to ``OUT`` (.npy)."""
    import json

    import bpy

    from . import animated
    from .world_map import bake_world

    blend, name, out, height, frame = args
    with bpy.data.libraries.load(blend, link=False) as (source, target):
        if name not in source.worlds:
            raise SystemExit(f"no world {name!r} in {blend}")
        target.worlds = [name]
    world = target.worlds[0]
    values = os.path.join(os.path.dirname(blend), VALUES_FILE)
    if os.path.exists(values):  # a render's frame: its animated values, its animation cleared
        with open(values, encoding="utf-8") as given:
            animated.apply(world, [tuple(v) for v in json.load(given)])
    radiance = bake_world(world, int(height), frame=int(frame))
    partial = out + ".part.npy"
    np.save(partial, radiance)
    os.replace(partial, out)  # whole or nothing: the parent reads it when the child has ended
    return 0

"""Other processes running Blender for work the main thread must not hold: the kernels' machine
code (``render.warmup_process``) and node-built worlds' bakes (``snapshot.world_process``).

A child is Blender's binary in background mode with factory settings, or — Blender as a Python
module — this Python, running this file as a script (``command``). The script lowers its own
priority, imports the add-on from its path as the package ``voxgi_child`` (the code of the
session that started it) and hands the rest of its arguments to that module's ``child_main``.
This file imports nothing of the add-on's, so the script can run it before the add-on is there.
"""
from __future__ import annotations

import atexit
import importlib
import importlib.util
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]  # the add-on's package directory
PACKAGE = "voxgi_child"  # the add-on's package name in a child


def command(module: str, args, nice: int = 19, register: bool = False) -> list[str]:
    """The command line of a child that runs ``module`` 's ``child_main(args)`` (``module``
    relative to the add-on's package, e.g. "render.warmup_process"), ``nice`` levels below
    its parent (by default the lowest priority: measured beside the Rendered view's draws, a
    bake child at 10 levels took their longest from 33–38 ms to 45–52 ms, at 19 its bakes
    came 0.5–0.9 s later), after registering the add-on if ``register`` (the scene settings a child that
    renders with VoxGI reads)."""
    import bpy

    ours = [str(ROOT), module, str(int(nice)), "1" if register else "0", *map(str, args)]
    binary = getattr(bpy.app, "binary_path", "")
    if binary and os.path.basename(binary).lower().startswith("blender"):
        return [binary, "-b", "--factory-startup", "--python", __file__, "--", *ours]
    return [sys.executable, __file__, *ours]


class Child:
    """A running child with a directory of its own (its inputs, its outputs, its log), which
    goes with it (``stop``). Every child still running when Blender exits is stopped."""

    def __init__(self, process: subprocess.Popen, directory: str):
        self.process, self.directory = process, directory

    @classmethod
    def start(cls, module: str, args, directory: str, nice: int = 19) -> Child:
        """Start ``module`` 's ``child_main(args)`` (``command``) with its output in
        ``directory``/log.txt; ``directory`` (``workspace``) is removed if it cannot start."""
        kwargs = {}
        if hasattr(subprocess, "IDLE_PRIORITY_CLASS"):  # Windows; POSIX children nice themselves
            kwargs["creationflags"] = subprocess.IDLE_PRIORITY_CLASS if nice >= 19 else \
                subprocess.BELOW_NORMAL_PRIORITY_CLASS
        try:
            with open(os.path.join(directory, "log.txt"), "wb") as log:
                process = subprocess.Popen(command(module, args, nice), stdin=subprocess.DEVNULL,
                                           stdout=log, stderr=subprocess.STDOUT, **kwargs)
        except BaseException:
            shutil.rmtree(directory, ignore_errors=True)
            raise
        child = cls(process, directory)
        _RUNNING.add(child)
        return child

    def path(self, name: str) -> str:
        return os.path.join(self.directory, name)

    def ended(self) -> int | None:
        """The child's exit code, None while it runs."""
        return self.process.poll()

    def tail(self, lines: int = 3) -> str:
        """The last lines of its output, for saying why it failed."""
        try:
            with open(self.path("log.txt"), "rb") as log:
                text = log.read().decode("utf-8", "replace").strip().splitlines()
        except OSError:
            text = []
        return " | ".join(text[-lines:]) or "no output"

    def stop(self) -> None:
        """Kill it if it still runs, and remove its directory."""
        _RUNNING.discard(self)
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        shutil.rmtree(self.directory, ignore_errors=True)


_RUNNING: set[Child] = set()


def workspace(prefix: str) -> str:
    """A new directory for a child (``Child.start``)."""
    return tempfile.mkdtemp(prefix=prefix)


@atexit.register
def _stop_all() -> None:
    for child in list(_RUNNING):
        child.stop()


def sees_images(tree, depth: int = 0) -> bool:
    """Whether a child reading a file that holds ``tree`` (a node tree, written with its images
    by absolute paths) sees its images as this session does: none of them (nor of its groups)
    lives only in this session's memory (generated, edited and not saved)."""
    import bpy

    if tree is None or depth > 8:
        return True
    for node in tree.nodes:
        image = getattr(node, "image", None)
        if image is not None:
            if image.is_dirty or image.source not in ("FILE", "TILED", "SEQUENCE", "MOVIE"):
                return False
            path = bpy.path.abspath(image.filepath, library=image.library)
            if image.packed_file is None and not (image.filepath and os.path.exists(path)) \
                    and image.source != "TILED":
                return False
        if not sees_images(getattr(node, "node_tree", None), depth + 1):
            return False
    return True


def lower_priority(increment: int) -> None:
    """The child's first step on POSIX: ``increment`` nice levels below its parent (the threads
    it starts, llvmpipe's and Cycles' included, inherit it). Done by the child itself, not
    before its exec: a ``preexec_fn`` makes Python fork the whole Blender process, 8–18 ms of
    the main thread for a 0.8 GB one, where without it the child is spawned for about 1 ms."""
    if increment > 0 and hasattr(os, "nice"):
        try:
            os.nice(increment)
        except OSError:  # not allowed here: the child runs at the user's priority
            return


def import_addon(root: str, register: bool = False):
    """Import the add-on at ``root`` as the package ``PACKAGE`` (registered if ``register``)."""
    spec = importlib.util.spec_from_file_location(
        PACKAGE, os.path.join(root, "__init__.py"), submodule_search_locations=[root])
    module = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = module
    spec.loader.exec_module(module)
    if register:
        module.register()
    return module


def main(argv: list[str]) -> int:
    """The child: ``ROOT MODULE NICE REGISTER ARGS…`` (after ``--`` when run by Blender's
    binary)."""
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    root, module, nice, register, *args = argv
    lower_priority(int(nice))
    import bpy  # noqa: F401 - Blender as a module: start it before the add-on

    import_addon(root, register=register == "1")
    return int(importlib.import_module(f"{PACKAGE}.{module}").child_main(args) or 0)


if __name__ == "__main__":
    # a normal exit: Mesa writes its shader cache from a thread of its own, flushed at exit
    sys.exit(main(sys.argv[1:]))

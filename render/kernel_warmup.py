"""The view's kernels compiled before a view needs them (docs/gi_pipeline.md "Kernels compiled
before the view needs them").

Entering Rendered mode compiles every kernel the first GI image uses, one per ``view_draw``
(``viewport_prepare.kernel_steps``): eleven on the demo box, so the first GI image could not
come before the eleventh draw. Most of them do not depend on the scene — the quick image's
shade, the gathers' upsampling and filter, the composition's surface and light sums, the
accumulation's three — only the BVH kernels do (their variants follow the scene's lights,
textures and cut-outs). While a file whose render engine is VoxGI is open in Blender's UI, a
timer compiles those scene-independent kernels (``kernel_steps`` without a scene, with the
file's settings), **one per tick**, a tick every ``STEP_SECONDS``: a compile of 1–20 ms
between two events, before the user switches a view to Rendered, which then compiles only the
scene's BVH variants. The getters are the views' own cached ones (``viewport_prepare.kernel_steps``), so
a kernel is compiled once whichever comes first.

A compile that took longer than ``SLOW_COMPILE`` (Mesa's shader cache empty: a first session
on a machine) spaces the next tick by ``SLOW_SECONDS``, so the warm-up never holds the main
thread for longer than one compile at a time. Nothing runs in background mode (no view to
enter) nor while F12 renders, and nothing once every kernel of the file's settings is compiled (the timer then only
looks every ``IDLE_SECONDS`` whether the settings or the engine changed).

The same timer starts, for a saved file, the process that builds the kernels' machine code in
Mesa's shader cache before any view needs it (``warmup_process``: what a machine's first
session would otherwise build in the view's draws, 40–640 ms each), and a child that bakes
the scene's node-built world before an F12 needs it (``world_process.bake_ahead``: F12 in the
UI renders on a job thread, where no bake can run). While F12 renders, it writes the material
bakes the render asks for to a child process and collects them (``bakes.RenderBakes``).
"""
from __future__ import annotations

import time

import bpy

from ..blender.snapshot import world_process
from ..blender.snapshot.bakes import render_bakes
from . import warmup_process
from .gpu_context import gpu_usable
from .gpu_gather import _glossy_shader

STEP_SECONDS = 0.1   # between two compiles
IDLE_SECONDS = 1.0   # between two looks when there is nothing to compile
SLOW_COMPILE = 0.030  # a compile longer than this spaces the next one by SLOW_SECONDS
SLOW_SECONDS = 1.0
RENDER_SECONDS = 0.1  # between two looks while F12 renders: whether it asks for bakes
SERVE_SECONDS = 0.02  # between two ticks of an F12's bakes (``bakes.RenderBakes``)

ENGINE = "VOXGI"
DEFAULT_REGION = (1280, 720)


def generic_steps(settings) -> tuple[tuple, list]:
    """(key, steps): the kernels of ``viewport_prepare.kernel_steps`` that no scene's features
    choose (the BVH kernels' variants are left out: they need the scene), with the lamps'
    glossy light (``glossy direct``, which every scene with a lamp uses), for the VoxGI
    settings ``settings`` (``Scene.voxgi``)."""
    from .viewport_prepare import kernel_key, kernel_steps

    key = kernel_key(None, settings)
    steps = kernel_steps(*key)
    steps.append(("glossy direct", 2, _glossy_shader))
    return key, steps


_warmup = None  # the KernelWarmup of the generic lists (not the views': their status counts)


def step(settings) -> str:
    """Compile the next scene-independent kernel for ``settings`` not compiled yet: its name,
    or "" when all are (counted in ``gpu_shaders.counters`` like the views' compiles)."""
    global _warmup
    from .viewport_prepare import KernelWarmup

    if _warmup is None:
        _warmup = KernelWarmup()
    key, steps = generic_steps(settings)
    return _warmup.step(key, steps, 2)


def done(settings) -> bool:
    """Whether every scene-independent kernel for ``settings`` is compiled (no GPU call)."""
    key, _ = generic_steps(settings)
    return _warmup is not None and (key, 2) in _warmup.done


def tick(scene) -> float:
    """One tick of the timer for the active ``scene``: a compile when it renders with VoxGI,
    some kernel is still to compile and the GPU can be used; the seconds until the next tick
    (an idle tick touches no GPU)."""
    if scene is None or scene.render.engine != ENGINE or not hasattr(scene, "voxgi") or \
            done(scene.voxgi) or not gpu_usable()[0]:
        return IDLE_SECONDS
    t0 = time.perf_counter()
    name = step(scene.voxgi)
    if not name:
        return IDLE_SECONDS
    return SLOW_SECONDS if time.perf_counter() - t0 > SLOW_COMPILE else STEP_SECONDS


def region_size(context) -> tuple[int, int]:
    """The largest 3D view's size in the open windows (where Rendered mode will draw), or
    ``warmup_process``'s default."""
    sizes = [(region.width, region.height)
             for window in getattr(context.window_manager, "windows", ())
             for area in window.screen.areas if area.type == "VIEW_3D"
             for region in area.regions if region.type == "WINDOW"]
    return max(sizes, key=lambda s: s[0] * s[1], default=DEFAULT_REGION)


def start_process(scene, context) -> bool:
    """Start the kernels' warm-up process for the open file when it is saved and renders
    with VoxGI (``warmup_process``: once per file version on this machine): whether it
    started."""
    if scene is None or scene.render.engine != ENGINE or not bpy.data.filepath:
        return False
    return warmup_process.processes.start(bpy.data.filepath, *region_size(context))


def _tick() -> float | None:
    """The timer (Blender's UI only: in background mode there is no view to enter)."""
    if bpy.app.background:
        return None
    if bpy.app.is_job_running("RENDER"):  # F12 compiles what it uses, in its own context
        # and may ask for material bakes it cannot write itself (bakes.RenderBakes)
        return SERVE_SECONDS if render_bakes.serve() else RENDER_SECONDS
    try:
        scene = getattr(bpy.context, "scene", None)
        start_process(scene, bpy.context)
        if scene is not None and scene.render.engine == ENGINE:
            world_process.bake_ahead(scene)
        return tick(scene)
    except Exception:  # noqa: BLE001 - a view compiles it again and reports what failed
        return None


def release() -> None:
    """Forget which lists are compiled (the shaders' caches are cleared with it)."""
    global _warmup
    _warmup = None


def register() -> None:
    if not bpy.app.background and not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=IDLE_SECONDS, persistent=True)
        render_bakes.served = True


def unregister() -> None:
    render_bakes.served = False
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)
    warmup_process.processes.stop()
    world_process.ahead.clear()

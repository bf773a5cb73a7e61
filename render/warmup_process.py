"""The kernels' machine code built by another process before a view needs it
(docs/gi_pipeline.md "A first session's kernels, built by another process").

In a machine's first session Mesa's shader cache is empty, and llvmpipe builds each kernel's
machine code at its first dispatch: 40–640 ms, on the main thread, in whichever draw of the
Rendered view dispatches it first (``kernel_warmup`` can only compile the GLSL ahead; the code
is built at the dispatch). No budget can split one such build. What can be done is to build it
before the view needs it, off Blender's main thread — in another process, since only the main
thread may hold Blender's GPU context: Mesa keeps what a process builds in its shader cache on
disk, and a later process whose kernels have the same source and state loads them from there in
1–25 ms.

So when a saved file whose render engine is VoxGI is open in Blender's UI, ``kernel_warmup``'s
timer starts, once per file version on the machine, **one background process at the lowest
priority** (``WarmupProcesses.start``): Blender (or the Python that has ``bpy``) in background
mode, running this module (``child_main``), which opens the file, draws the scene camera's view in
Rendered mode into an offscreen buffer of the largest 3D view's size until it has converged
(every kernel of the view's slices, for the file's own lights, textures and cut-outs), and
then runs two more children, each a process of its own: a new session entering Rendered mode
on the cache the first one filled, to its first tile — the variants of a session's first draws
(the quick image, the first coarse image), which the first child's draws, slow while they
build, go without — and small F12 previews (the F12 kernels; in a process that had built the
view's variant of a kernel, llvmpipe kept F12's variant of it out of the cache). It touches
nothing of the user's session: it reads the saved file and writes only Mesa's cache and a stamp
(``stamp_path``) that says this file version is warmed. The children start as every child
of the add-on does (``blender.child_process``). ``VOXGI_NO_WARMUP_PROCESS`` (any non-empty value) turns it off.
"""
from __future__ import annotations

import hashlib
import os
import pathlib
import subprocess
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]  # the add-on's package directory
DISABLE = "VOXGI_NO_WARMUP_PROCESS"
SECONDS = 180.0   # the child's own limit (it stops there, whatever is left)
# the small F12 previews: their kernels — at one gather point a pixel, and at a stride of 2
# (the upsampling's: a frame past 160 × 120 pixels) — at sizes not powers of two, as a frame's
F12_SIZES = ((96, 54), (208, 117))
DONE = "VOXGI-WARMUP done"
# the children's phases (``warm``), each a process of its own: llvmpipe keeps a kernel's code
# built in a process that had built another variant of it in memory out of the cache on disk
# (the F12 glossy gather's after the view's: 0.6 s again in the next session)
CONVERGE, ENTER, F12 = "converge", "enter", "f12"


def stamp_path(blend: str, cache_dir: str | None = None) -> pathlib.Path:
    """Where the stamp of ``blend``'s current version lies: a hash of the file's path, size
    and modification time, the add-on's kernels' sources and Mesa's cache directory, under
    ``cache_dir`` (default: the user's cache directory, ``voxgi/warmed``)."""
    stat = os.stat(blend)
    digest = hashlib.sha1()
    for part in (os.path.abspath(blend), stat.st_size, stat.st_mtime_ns,
                 os.environ.get("MESA_SHADER_CACHE_DIR", ""), _sources_digest()):
        digest.update(str(part).encode())
    base = pathlib.Path(cache_dir) if cache_dir else \
        pathlib.Path(os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache") / \
        "voxgi" / "warmed"
    return base / digest.hexdigest()


_SOURCES: list[str] = []


def _sources_digest() -> str:
    """A hash of the kernels' GLSL sources (a new version of the add-on warms again)."""
    if not _SOURCES:
        digest = hashlib.sha1()
        for path in sorted((ROOT / "render" / "shaders").glob("*.glsl")):
            digest.update(path.read_bytes())
        _SOURCES.append(digest.hexdigest())
    return _SOURCES[0]


def command(blend: str, width: int, height: int, phase: str = "") -> list[str]:
    """The child's command line (``blender.child_process``): at the lowest priority, the
    add-on registered, running ``child_main``."""
    from ..blender.child_process import command as child_command

    return child_command("render.warmup_process", [blend, int(width), int(height), phase or CONVERGE],
                         nice=19, register=True)


def launch(blend: str, width: int, height: int, wait: bool = False,
           env: dict | None = None) -> subprocess.Popen:
    """Start the child for ``blend`` at the lowest priority (its output discarded unless
    ``wait``: then it is waited for and its output kept in the returned process's
    ``output``)."""
    kwargs = {}
    if hasattr(subprocess, "IDLE_PRIORITY_CLASS"):  # Windows; POSIX children nice themselves
        kwargs["creationflags"] = subprocess.IDLE_PRIORITY_CLASS
    out = subprocess.PIPE if wait else subprocess.DEVNULL
    process = subprocess.Popen(command(blend, width, height), stdout=out,
                               stderr=subprocess.STDOUT if wait else subprocess.DEVNULL,
                               stdin=subprocess.DEVNULL, env=env, **kwargs)
    if wait:
        process.output = process.communicate(timeout=SECONDS + 120.0)[0].decode(
            "utf-8", "replace")
    return process


class WarmupProcesses:
    """The children this session started (``kernel_warmup``'s timer): at most one at a time,
    one per file version (its stamp, written when the child says it is done)."""

    def __init__(self, cache_dir: str | None = None):
        self.cache_dir = cache_dir
        self.running: tuple[subprocess.Popen, pathlib.Path] | None = None
        self.tried: set[pathlib.Path] = set()

    def poll(self) -> bool:
        """Whether a child is still running (a finished one's stamp written)."""
        if self.running is None:
            return False
        process, stamp = self.running
        code = process.poll()
        if code is None:
            return True
        self.running = None
        if code == 0:
            stamp.parent.mkdir(parents=True, exist_ok=True)
            stamp.write_text(time.strftime("%Y-%m-%d %H:%M:%S\n"))
        return False

    def start(self, blend: str, width: int, height: int) -> bool:
        """Start a child for ``blend`` unless one runs, it is warmed already (its stamp) or
        was tried in this session, or ``VOXGI_NO_WARMUP_PROCESS`` is set: whether it
        started."""
        if os.environ.get(DISABLE) or not blend or not os.path.isfile(blend) or self.poll():
            return False
        stamp = stamp_path(blend, self.cache_dir)
        if stamp.exists() or stamp in self.tried:
            return False
        self.tried.add(stamp)
        try:
            self.running = (launch(blend, width, height), stamp)
        except OSError:
            return False
        return True

    def status(self) -> str:
        """The sidebar's line while a child runs (nothing changed; "" when none runs)."""
        if self.running is None or self.running[0].poll() is not None:
            return ""
        return "Building the kernels in the background (this machine's first session with " \
            "this file)"

    def stop(self) -> None:
        if self.running is not None and self.running[0].poll() is None:
            self.running[0].kill()
        self.running = None


processes = WarmupProcesses()  # the open file's children (``kernel_warmup``'s timer; UI only)


# ------------------------------------------------------------------ the child

class _Engine:
    """What ``viewport.view_draw`` uses of a ``RenderEngine`` (bpy makes none headless)."""

    redraws = 0

    def bind_display_space_shader(self, scene):
        """Nothing to bind: the child draws into an offscreen buffer nobody sees."""

    def unbind_display_space_shader(self):
        """Nothing was bound."""

    def tag_redraw(self):
        self.redraws += 1

    def update_stats(self, stats, info):
        """No header to show the status line in."""


def _view(scene, depsgraph, width, height):
    """(view, window) matrices of the scene camera, or of a view onto the scene's objects."""
    from mathutils import Matrix, Vector

    camera = scene.camera
    if camera is not None:
        return (camera.matrix_world.inverted(),
                camera.calc_matrix_camera(depsgraph, x=width, y=height))
    centre = Vector((0.0, 0.0, 0.0))
    eye = centre + Vector((6.0, -6.0, 4.0))
    view = Matrix.Translation(eye) @ (centre - eye).to_track_quat("-Z", "Y").to_matrix() \
        .to_4x4()
    aspect = width / max(height, 1)
    near, far, f = 0.1, 100.0, 2.0
    window = Matrix(((f / aspect, 0, 0, 0), (0, f, 0, 0),
                     (0, 0, (far + near) / (near - far), 2 * far * near / (near - far)),
                     (0, 0, -1, 0)))
    return view.inverted(), window


def warm(blend: str, width: int, height: int, phase: str = CONVERGE,
         seconds: float = SECONDS) -> str:
    """A child's work in this process (module doc): open ``blend`` and draw its view in
    Rendered mode at ``width`` × ``height`` until converged (``CONVERGE``) or to its first
    tile (``ENTER``); or render small F12 previews (``F12``). Returns a line saying what was
    done."""
    import types

    import bpy
    import gpu

    from ..blender import jobs
    from .gpu_context import ensure_gpu_context
    from .gpu_shaders import counters
    from .pipeline import render_scene_passes
    from .viewport import view_draw, view_update

    started = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    scene = bpy.context.scene
    ready, why = ensure_gpu_context()
    if not ready:
        raise RuntimeError(f"no GPU context: {why}")
    jobs.synchronous = False
    before = counters.compiles
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = _view(scene, depsgraph, width, height)
    context = types.SimpleNamespace(
        region=types.SimpleNamespace(width=width, height=height),
        region_data=types.SimpleNamespace(view_matrix=view, window_matrix=window))
    offscreen = gpu.types.GPUOffScreen(width, height)
    draws = 0

    def enter(engine, until):  # Rendered mode entered: draws until ``until(renderer)``
        nonlocal draws
        view_update(engine, context, depsgraph)
        while time.perf_counter() - started < seconds:
            jobs.drain()
            redraws = engine.redraws
            with offscreen.bind():
                view_draw(engine, context, depsgraph)
                # the draws' dispatches run at the buffer's use, as at Blender's swap
                offscreen.texture_color.read()
            draws += 1
            if until(engine.voxgi_viewport, engine.redraws == redraws):
                return
            if engine.redraws == redraws:
                time.sleep(0.01)  # waiting for the worker's job

    try:
        if phase == CONVERGE:
            # every kernel of the view's slices and its radiance cache
            enter(_Engine(), lambda r, idle: idle and r.progressive.converged and
                  (r.cache.generation > 0 or not r.cache.resume()))
        elif phase == ENTER:
            # a new session's first draws on the cache the first child filled, to the first
            # tile after the first GI image: the quick image's and the first coarse image's
            # variants, which that child's slower (building) draws went without
            enter(_Engine(), lambda r, idle: r.traces >= 2 or idle and r.progressive.converged)
        jobs.wait_idle(60.0)
    finally:
        offscreen.free()
    if phase == F12 and scene.camera is not None:
        for size in F12_SIZES:
            if time.perf_counter() - started < seconds:
                render_scene_passes(bpy.context, scene, None, *size)
    return (f"{DONE}: {draws} draws, {counters.compiles - before} kernels compiled, "
            f"{time.perf_counter() - started:.1f} s")


def child_main(args: list[str]) -> int:
    """A child (``blender.child_process``): ``BLEND WIDTH HEIGHT PHASE``. The ``CONVERGE``
    child then runs the ``ENTER`` and ``F12`` ones, each a process of its own."""
    blend, width, height, phase = args
    print(warm(blend, int(width), int(height), phase), flush=True)
    code = 0
    for after in (ENTER, F12) if phase == CONVERGE else ():
        ran = subprocess.run(command(blend, int(width), int(height), after),
                             stdin=subprocess.DEVNULL, capture_output=True, text=True,
                             timeout=SECONDS + 120.0)
        done = [line for line in ran.stdout.splitlines() if line.startswith(DONE)]
        print(f"{done[-1] if done else after + ' failed'} ({after}, a process of its own)",
              flush=True)
        code = code or ran.returncode
    return code

"""Entering Rendered mode, measured where users feel it (docs/gi_pipeline.md "Entering
Rendered mode"): the main thread's time per ``view_draw`` from entering the 3D view's Rendered
mode to the first image, then through an orbit, a slider drag and an object move. Run by the
``viewport`` section on the demo box (``bench_viewport.py``) and by the ``imported`` section on
the 140k-triangle imported diorama of ``diorama_scene.py``
(``bench_entering_imported_blender.py``); standalone: ``.venv/bin/python
tools/bench/bench_entering_blender.py --scene box|diorama [--quick]``.

As in an interactive session: the engine worker runs the session's update jobs on its thread
and the view prepares its GPU scene on its own, drained between draws as the timer would, with
Blender's main-loop sleep (5 ms) between two draws; each ``view_draw`` (the stand-in engine, a
1280×720 region, default settings) is timed to the GPU's finish (waited for without the GIL,
as Blender's buffer swap: ``gpu_finish``). Per phase it reports the
longest draw, the median, the time to the first image (the quick image, then the first GI
image) and, per kind of step a draw runs (a shader compile, a scene part sent, a vertex-batch
chunk, the quick image, a slice's stage), the longest one — the floor of that phase where a
single step cannot be cut (one compile, one G-buffer chunk). The entering rows are measured
again in a second process after the kernels' warm-up (``--warmed``: what the add-on's timer
compiles while the file is open in Solid mode, render/kernel_warmup.py), and in a third with
Mesa's shader cache off (``MESA_SHADER_CACHE_DISABLE``): a first-ever session, every kernel
compiled by LLVM.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parents[1] / "tests" / "blender")]

REGION = (1280, 720)
# Blender's main loop sleeps 5 ms when it handled no event (wm_window_events_process), then
# redraws what was tagged: the other threads run meanwhile, as they do here between two draws
EVENT_LOOP_SLEEP = 0.005
# Measured before the view was made ready a step per draw (this benchmark on the code of that
# time, this machine, load 1–4.5; docs/gi_pipeline.md "Entering Rendered mode"): the first
# view_draw did everything
BEFORE = {"box": "first view_draw 0.78–1.18 s (3.3–6.5 s with Mesa's shader cache off), the "
                 "first image in it; orbit 12–13 ms; object move 24–30 ms",
          "diorama": "first view_draw 1.6–4.5 s (4.5–9.2 s with Mesa's shader cache off), the "
                     "first image in it; orbit 160–410 ms; lamp drag 183–317 ms; object move "
                     "0.7–1.2 s"}


_GL = []


def gpu_finish() -> None:
    """Wait for the GPU's finish without holding Python's GIL, as Blender does (it swaps the
    region's buffers outside Python): ``glFinish`` through ctypes, which lets go of the GIL
    while it waits — the ``gpu`` module's read-back holds it, which stalled the view's
    preparing thread three times as long as the draw (a BVH build 0.45 → 1.4 s). The
    read-back after it then finds nothing left to wait for."""
    if not _GL:
        import ctypes

        try:
            _GL.append(ctypes.CDLL("libGL.so.1").glFinish)
        except (OSError, AttributeError):
            _GL.append(None)
    if _GL[0] is not None:
        _GL[0]()


def _kind(label: str) -> str:
    """The kind of step a ``ViewportRenderer.timings`` label names."""
    if label.startswith("compile"):
        return "shader compile"
    if label.startswith("scene"):
        return "scene part sent"
    if label.startswith("stage ("):  # a slice's stage, named by its frame stage
        return "slice stage"
    if label in ("vertex batch", "raster first draw", "quick image",
                 "radiance cache stage", "snapshot read"):
        return label
    return ""


class Session:
    """A stand-in engine drawing ``scene`` into a region-sized offscreen, each draw timed."""

    def __init__(self, scene):
        import bpy
        import gpu
        from stand_in_engine import StandInEngine

        from voxgi.blender.updates import records_from_depsgraph
        from voxgi.blender.viewport_session import live_gi

        self.scene = scene
        self.depsgraph = bpy.context.evaluated_depsgraph_get()
        width, height = REGION
        camera = scene.camera
        self.window = camera.calc_matrix_camera(self.depsgraph, x=width, y=height)
        self.view = camera.matrix_world.inverted()
        self.offscreen = gpu.types.GPUOffScreen(width, height)
        self.engine = StandInEngine()
        self.live = live_gi(scene.name_full)
        self.records = []
        self.handler = lambda _s, graph: self.records.extend(
            records_from_depsgraph(graph, self.live.index))
        bpy.app.handlers.depsgraph_update_post.append(self.handler)
        self.draws = []  # (seconds, timings, shown, traces) of every draw
        self.started = time.perf_counter()

    def context(self, view):
        import types

        return types.SimpleNamespace(
            region=types.SimpleNamespace(width=self.offscreen.width,
                                         height=self.offscreen.height),
            region_data=types.SimpleNamespace(view_matrix=view, window_matrix=self.window))

    def update(self, records=None) -> float:
        """``view_update`` (records: the depsgraph's since the last; None: all): seconds."""
        from voxgi.render.viewport import view_update

        t0 = time.perf_counter()
        if records is None:
            view_update(self.engine, self.context(self.view), self.depsgraph)
        else:
            self.live.update(self.scene, self.depsgraph, records)
        return time.perf_counter() - t0

    def draw(self, view=None):
        """One timed ``view_draw`` (after the timer's drain): (seconds, renderer)."""
        import gpu

        from voxgi.blender import jobs
        from voxgi.render.viewport import view_draw

        time.sleep(EVENT_LOOP_SLEEP)  # Blender's main loop between two redraws
        t0 = time.perf_counter()
        jobs.drain()
        self.asked = self.engine.redraws
        drained = time.perf_counter() - t0
        with self.offscreen.bind():
            t0 = time.perf_counter()
            view_draw(self.engine, self.context(view or self.view), self.depsgraph)
            gpu_finish()
            gpu.state.active_framebuffer_get().read_color(0, 0, 1, 1, 4, 0, "FLOAT")
            seconds = time.perf_counter() - t0
        renderer = self.engine.voxgi_viewport
        # the timer's drain (main thread too) and the draw's start, for --trace
        self.draws.append((seconds, {**renderer.timings, "(drain)": drained,
                                     "(at)": t0 - self.started},
                           renderer.shown, renderer.traces))
        return seconds, renderer

    def wait_for_redraw(self, limit: float = 5.0) -> None:
        """Until the last draw's view asks for a redraw — at once, or from the timer a view
        that waits for its preparing thread leaves (``viewport_prepare.wake_tick``, run here
        as Blender's event loop would) — as Blender redraws a region only when tagged."""
        from voxgi.blender import jobs
        from voxgi.render import viewport_prepare

        started = time.perf_counter()
        while self.engine.redraws == self.asked and time.perf_counter() - started < limit:
            time.sleep(viewport_prepare.WAKE_POLL)
            viewport_prepare.wake_tick()
            jobs.drain()

    def close(self):
        import bpy

        bpy.app.handlers.depsgraph_update_post.remove(self.handler)
        self.offscreen.free()


def _phase(draws) -> dict:
    """Longest, median and count of ``draws``, and the longest step of each kind."""
    seconds = [d[0] for d in draws]
    steps: dict[str, tuple[float, str]] = {}
    for _, timings, _, _ in draws:
        for label, value in timings.items():
            kind = _kind(label)
            if kind and value > steps.get(kind, (0.0, ""))[0]:
                steps[kind] = (value, label)
    longest = max(range(len(draws)), key=lambda i: seconds[i]) if draws else 0
    return {"longest": max(seconds, default=0.0), "median": statistics.median(seconds or [0.0]),
            "count": len(seconds), "steps": steps,
            "longest_labels": draws[longest][1] if draws else {}}


def _steps_text(phase) -> str:
    parts = [f"{kind} {value * 1000:.0f} ms ({label.removeprefix('compile ')})"
             if kind == "shader compile" else f"{kind} {value * 1000:.0f} ms"
             for kind, (value, label) in sorted(phase["steps"].items(), key=lambda x: -x[1][0])]
    return "; ".join(parts) or "—"


def warm_kernels(scene) -> tuple[int, float, float]:
    """What the add-on's timer does while the file is open in Solid mode
    (``render/kernel_warmup.py``): the scene-independent kernels compiled one per tick;
    (compiles, longest tick, all ticks) in seconds."""
    from voxgi.render import kernel_warmup

    ticks = []
    while True:
        t0 = time.perf_counter()
        name = kernel_warmup.step(scene.voxgi)
        if not name:
            break
        ticks.append(time.perf_counter() - t0)
    return len(ticks), max(ticks, default=0.0), sum(ticks)


def measure(scene, name: str, quick: bool, entering_only: bool = False,
            trace: list | None = None, warmed: bool = False) -> list:
    """The rows (module doc) for ``scene`` (``name``: "box" or "diorama"); entering_only: up
    to the first GI image; trace: a list given every draw's (seconds, timings, shown,
    traces); warmed: the kernels' warm-up (``warm_kernels``) before entering."""
    import math

    import bpy
    from mathutils import Matrix

    from voxgi.blender import jobs
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    jobs.synchronous = False
    rows = []
    if warmed:
        count, longest, total = warm_kernels(scene)
        rows.append((f"{name}: the kernels' warm-up with the file open (Solid mode): longest "
                     "timer tick", longest,
                     f"goal ≤ 30 ms; {count} kernels compiled, one per tick, "
                     f"{total * 1000:.0f} ms in all"))
        name = f"{name}, kernels warmed"
    session = Session(scene)
    if trace is not None:
        session.draws = trace
    limit = 120.0
    # 1. entering Rendered mode: view_update, then draws until the first GI image
    started = session.started = time.perf_counter()
    update = session.update()
    first_quick = first_gi = None
    while time.perf_counter() - started < limit:
        _, renderer = session.draw()
        now = time.perf_counter() - started
        if first_quick is None and renderer.texture is not None:
            first_quick = now
        if renderer.traces:
            first_gi = now
            break
        session.wait_for_redraw()
    entering = _phase(session.draws)
    quick_index = next((i for i, d in enumerate(session.draws) if d[2] == "Quick"), None)
    to_quick = _phase(session.draws[:quick_index + 1]) if quick_index is not None else entering
    rows.append((f"{name}: view_update on entering (the snapshot, or a slice of its mesh reads)",
                 update, "main thread"))
    rows.append((f"{name}: longest view_draw, entering → first image (quick image)",
                 to_quick["longest"],
                 f"goal ≤ 30 ms; {to_quick['count']} draws, median "
                 f"{to_quick['median'] * 1000:.0f} ms; longest steps: {_steps_text(to_quick)}; "
                 f"before: {BEFORE[name.split(',')[0]]}"))
    rows.append((f"{name}: longest view_draw, entering → first GI image", entering["longest"],
                 f"goal ≤ 30 ms; {entering['count']} draws, median "
                 f"{entering['median'] * 1000:.0f} ms; longest steps: {_steps_text(entering)}"))
    goal = "0.2 s" if name.startswith("box") else "1 s"
    rows.append((f"{name}: entering → first image drawn (the quick image)", first_quick or 0.0,
                 f"goal ≤ {goal}"))
    rows.append((f"{name}: entering → first GI image drawn", first_gi or 0.0,
                 f"goal ≤ {goal}; its GPU scene (triangles, BVH, lights) prepared on the "
                 "view's thread meanwhile, the session's update job after it"))
    if entering_only:
        session.close()
        return rows
    # let the image refine a moment, the jobs finish
    jobs.wait_idle(600)
    for _ in range(20 if quick else 60):
        session.draw()

    def orbit(k):
        return session.view @ Matrix.Rotation(math.radians(2.0 * k), 4, "Z")

    # 2. an orbit: a new view every draw
    mark = len(session.draws)
    steps = 8 if quick else 16
    for k in range(1, steps + 1):
        session.draw(orbit(k))
    for _ in range(200):  # held still: its first image
        seconds, renderer = session.draw(orbit(steps))
        if renderer.progressive.last is not None and not renderer.progressive.coarse_pending:
            break
    phase = _phase(session.draws[mark:mark + steps])
    rows.append((f"{name}: orbit, 2° per draw: longest view_draw", phase["longest"],
                 f"goal ≤ 30 ms; median {phase['median'] * 1000:.0f} ms over {phase['count']} "
                 f"draws; longest steps: {_steps_text(phase)}"))
    still = _phase(session.draws[mark + steps:])
    rows.append((f"{name}: orbit held still → its first image: longest view_draw",
                 still["longest"], f"{still['count']} draws; longest steps: "
                                   f"{_steps_text(still)}"))
    view = orbit(steps)
    session.view = view

    # 3. a slider drag: a lamp's power, a new value every draw
    lamp = next(o for o in scene.objects if o.type == "LIGHT")
    mark = len(session.draws)
    for k in range(steps):
        session.records.clear()
        lamp.data.energy *= 1.05
        bpy.context.view_layer.update()
        t0 = time.perf_counter()
        session.update(list(session.records))
        session.draws.append((time.perf_counter() - t0, {}, "view_update", 0))
        session.draw(view)
    drag = _phase([d for d in session.draws[mark:] if d[2] != "view_update"])
    updates = [d[0] for d in session.draws[mark:] if d[2] == "view_update"]
    rows.append((f"{name}: slider drag ({lamp.name}'s power, every draw): longest view_draw",
                 drag["longest"],
                 f"goal ≤ 30 ms; median {drag['median'] * 1000:.0f} ms; view_update "
                 f"(light snapshot + submit) longest {max(updates) * 1000:.0f} ms; longest "
                 f"steps: {_steps_text(drag)}"))
    jobs.wait_idle(600)
    for _ in range(20):
        session.draw(view)

    # 4. an object move: once, then draws until its first GI image
    mover = next(o for o in scene.objects if o.type == "MESH" and o.name in
                 ("Rotating Sphere", "Rock 0")) if any(
        o.name in ("Rotating Sphere", "Rock 0") for o in scene.objects) else \
        next(o for o in scene.objects if o.type == "MESH")
    session.records.clear()
    mover.location.x += 0.05
    bpy.context.view_layer.update()
    mark = len(session.draws)
    traces = session.engine.voxgi_viewport.traces
    t0 = time.perf_counter()
    move_update = session.update(list(session.records))
    latency = None
    while time.perf_counter() - t0 < limit:
        _, renderer = session.draw(view)
        if renderer.traces > traces and renderer.shown in ("Coarse", "Refining", "Converged"):
            latency = time.perf_counter() - t0
            break
    move = _phase(session.draws[mark:])
    rows.append((f"{name}: object move ({mover.name}) → its first GI image: longest view_draw",
                 move["longest"],
                 f"goal ≤ 30 ms; {move['count']} draws, first GI after "
                 f"{(latency or 0.0) * 1000:.0f} ms (view_update {move_update * 1000:.0f} ms); "
                 f"longest steps: {_steps_text(move)}"))
    jobs.wait_idle(600)
    session.close()
    return rows


def build(name: str):
    """The scene ``name`` in a factory-empty file: the demo box or the imported diorama."""
    import bpy

    if name == "box":
        from bench_blender import demo_snapshot

        return demo_snapshot()[0]
    import diorama_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    diorama_scene.diorama(scene)
    return scene


def cold_rows(name: str, quick: bool, warmed: bool = False) -> list:
    """``measure``'s entering rows in a fresh process with Mesa's shader cache off; warmed:
    with it on, after the kernels' warm-up (``warm_kernels``: the file open a moment in Solid
    mode before the view enters Rendered mode)."""
    import subprocess

    env = dict(os.environ)
    if not warmed:
        env["MESA_SHADER_CACHE_DISABLE"] = "true"
    cmd = [sys.executable, str(pathlib.Path(__file__).resolve()), "--scene", name,
           "--warmed" if warmed else "--cold", "--rows", "--quick"]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(f"the {'warmed' if warmed else 'cold'} run failed:\n"
                           f"{done.stderr[-2000:]}")
    return _printed_rows(done.stdout)


def _printed_rows(stdout: str) -> list:
    """The (what, seconds, note) rows a ``--rows`` run printed."""
    rows = []
    for line in stdout.splitlines():
        if line.startswith("ROW\t"):
            _, what, seconds, note = line.split("\t", 3)
            rows.append((what, float(seconds), note))
    return rows


def after_warmup_rows(name: str, quick: bool, blend: str) -> list:
    """``measure``'s entering rows in a machine's first session (a new, empty Mesa shader
    cache) after the kernels' warm-up process (``render/warmup_process.py``) has run on the
    saved ``blend``, as the add-on's timer starts it when the file is opened in the UI."""
    import subprocess
    import tempfile

    from voxgi.render import warmup_process

    cache = tempfile.mkdtemp(prefix="voxgi-bench-mesa-")
    env = {k: v for k, v in os.environ.items() if k != "MESA_SHADER_CACHE_DISABLE"}
    env["MESA_SHADER_CACHE_DIR"] = cache
    t0 = time.perf_counter()
    child = warmup_process.launch(blend, *REGION, wait=True, env=env)
    seconds = time.perf_counter() - t0
    if child.returncode != 0:
        raise RuntimeError(f"the warm-up process failed:\n{child.output[-2000:]}")
    cmd = [sys.executable, str(pathlib.Path(__file__).resolve()), "--scene", name,
           "--fresh", "--rows", "--quick"]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(f"the run after the warm-up failed:\n{done.stderr[-2000:]}")
    rows = [(f"{name}: the kernels' warm-up process on the saved file (nice 19)", seconds,
             "a machine's first session: Mesa's shader cache empty before it")]
    rows += [(f"{what} — a first-ever session after the warm-up process", value, note)
             for what, value, note in _printed_rows(done.stdout)]
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", choices=("box", "diorama"), default="box")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cold", action="store_true", help="(set by cold_rows) Mesa cache off")
    ap.add_argument("--fresh", action="store_true",
                    help="(set by after_warmup_rows) entering only, on the cache it filled")
    ap.add_argument("--rows", action="store_true", help="print tab-separated rows only")
    ap.add_argument("--entering", action="store_true",
                    help="entering Rendered mode only (to the first GI image), no cold run")
    ap.add_argument("--warmed", action="store_true",
                    help="entering after the kernels' warm-up (render/kernel_warmup.py)")
    ap.add_argument("--trace", action="store_true",
                    help="print every draw's time and steps (renderer.timings) after the rows")
    args = ap.parse_args(argv)
    from bench_blender import load_addon, print_table

    load_addon()
    scene = build(args.scene)
    blend = None
    if not (args.entering or args.warmed or args.cold or args.fresh or args.rows):
        import tempfile

        import bpy

        blend = os.path.join(tempfile.mkdtemp(prefix="voxgi-bench-"), f"{args.scene}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)  # for the warm-up process
    triangles = sum(len(p.vertices) - 2 for o in scene.objects if o.type == "MESH"
                    for p in o.data.polygons)
    draws = []
    rows = measure(scene, args.scene, args.quick,
                   entering_only=args.cold or args.fresh or args.entering or
                   args.warmed and args.rows,
                   trace=draws, warmed=args.warmed)
    if args.cold:
        rows = [(f"{what} — Mesa shader cache off (a first-ever session)", seconds, note)
                for what, seconds, note in rows if "entering" in what]
    if args.fresh:
        rows = [row for row in rows if "entering" in row[0]]
    if args.trace:
        for k, (seconds, timings, shown, _) in enumerate(draws):
            steps = ", ".join(f"{label} {value * 1000:.1f}" for label, value in timings.items())
            print(f"draw {k:3d} {seconds * 1000:6.1f} ms {shown:10s} {steps}")
    if args.rows:
        for what, seconds, note in rows:
            print(f"ROW\t{what}\t{seconds}\t{note}")
        return 0
    if not args.entering and not args.warmed:
        rows += cold_rows(args.scene, args.quick, warmed=True)
        rows += cold_rows(args.scene, args.quick)
        if blend is not None:
            rows += after_warmup_rows(args.scene, args.quick, blend)
    print_table(f"### Entering Rendered mode and live edits: {args.scene} ({triangles:,} "
                f"triangles), view_draw at {REGION[0]}×{REGION[1]}, default settings, Mesa "
                f"llvmpipe ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at "
                "the end); each draw's main-thread time to the GPU's finish", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())

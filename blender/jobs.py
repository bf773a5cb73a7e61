"""Engine jobs: run ``fn(cancel) -> result`` on ONE background worker thread.

The main thread takes the snapshot (bpy) and submits a function of engine code only; the
worker never touches bpy. Outcomes come back through a ``queue.Queue`` that the main thread
drains, either from a ``bpy.app.timers`` callback (registered while a job runs, gone when
idle) or by calling ``drain()``; the job's callbacks (``on_done``, ``on_cancel``,
``on_error``) run there, on the main thread, and may use bpy.

* One job per scene counts: a newer submission for the same scene supersedes the older one
  (its cancel event is set and whatever it returns is discarded without callbacks). A
  submission that lets the running job finish (``finish_running``: short jobs, such as the
  frames of a playing animation) supersedes only a job still waiting in the queue: the
  running one is applied, then the newest waiting one runs — frames are dropped, never
  queued (docs/gi_pipeline.md "Posed updates").
* ``cancel(scene_name)`` sets the job's cancel event; the job becomes 'cancelled' once the
  worker has let go of it (next ``drain``), and even a result it still returns is dropped.
* In background mode (``bpy.app.background``: scripts, tests) ``submit`` waits for the job
  and applies it before returning, so callers stay synchronous; a job that takes longer than
  a second prints a progress line at most once per second (``ProgressPrinter``).
* A job may carry a ``Progress`` (fraction and text written by the worker, read by the main
  thread): the sidebar shows it, and while jobs run interactively the timer drives the window
  manager's progress bar and the status bar text.

bpy facts this relies on (Blender 5.0, checked with the ``bpy`` module):
* Without an event loop (the ``bpy`` module, ``blender --background``) timers registered with
  ``bpy.app.timers`` never fire: call ``drain()``.
* Loading a file, ``wm.read_factory_settings`` included, removes every timer registered
  without ``persistent=True``, and runs the load_pre/load_post handlers.
* ``bpy.app.timers.unregister`` of a function that is not registered raises ValueError.
"""
from __future__ import annotations

import contextlib
import os
import queue
import sys
import threading
import time
import traceback
from typing import Any, Callable

import bpy

from ..voxgi_addon.errors import VoxGICancelled
from .redraw import tag_sidebars

STATES = ("running", "done", "cancelled", "failed")
TICK_SECONDS = 0.2  # timer interval while a job runs (also the panel's elapsed-time refresh)
JOIN_TIMEOUT = 5.0  # seconds unregister waits for the worker to stop

# None: wait for every job when ``bpy.app.background``; True/False force it (tests).
synchronous: bool | None = None


def runs_synchronously() -> bool:
    return bool(bpy.app.background) if synchronous is None else synchronous


class Progress:
    """How far a job is: ``fraction`` in 0..1 and a short ``text``. The worker calls it; the
    main thread reads the attributes (single assignments, safe across threads)."""

    def __init__(self):
        self.fraction = 0.0
        self.text = ""

    def __call__(self, fraction: float, text: str = "") -> None:
        self.fraction = min(1.0, max(0.0, float(fraction)))
        if text:
            self.text = text


class ProgressPrinter:
    """Progress lines for background runs: none in the first ``interval`` seconds, then at
    most one per ``interval``. ``clock`` is injectable for tests."""

    def __init__(self, label: str, interval: float = 1.0, clock=time.perf_counter, out=print):
        self.label, self.interval, self.clock, self.out = label, interval, clock, out
        self.start = clock()
        self.last = self.start

    def tick(self, progress: "Progress | None") -> bool:
        """Print a line if one is due; returns whether it printed."""
        now = self.clock()
        if now - self.last < self.interval:
            return False
        self.last = now
        done = "" if progress is None else f" {progress.fraction * 100:.0f}%"
        what = "" if progress is None or not progress.text else f" ({progress.text})"
        self.out(f"VoxGI: {self.label}…{done}{what}, {now - self.start:.1f} s", flush=True)
        return True


class Job:
    """One submission. ``state`` and the callbacks belong to the main thread.

    state : 'running' until the main thread has applied the outcome, then 'done',
        'cancelled' or 'failed'.
    result : what ``fn`` returned ('done' only); error : the exception ('failed' only).
    """

    def __init__(self, scene_name: str, fn, label: str, on_done, on_cancel, on_error,
                 progress: Progress | None = None):
        self.scene_name = scene_name
        self.label = label
        self.progress = progress
        self.fn: Callable[[Callable[[], bool]], Any] | None = fn
        self.on_done, self.on_cancel, self.on_error = on_done, on_cancel, on_error
        self.state = "running"
        self.result: Any = None
        self.error: BaseException | None = None
        self.submitted_at = time.perf_counter()
        self.started = False  # written by the worker when it begins the job
        self.finished_at: float | None = None  # written by the worker
        self.superseded = False  # discarded without callbacks
        self._cancel = threading.Event()
        self._finished = threading.Event()  # the worker is done with it

    @property
    def cancel_requested(self) -> bool:
        return self._cancel.is_set()

    @property
    def finished(self) -> bool:
        """True once the worker has let go of the job (its outcome may not be applied yet)."""
        return self._finished.is_set()

    @property
    def elapsed(self) -> float:
        """Seconds since submission, frozen when the worker finished it."""
        end = self.finished_at if self.finished_at is not None else time.perf_counter()
        return end - self.submitted_at

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the worker is done with the job; True unless the timeout expired."""
        return self._finished.wait(timeout)

    def __repr__(self) -> str:
        return f"<Job {self.label!r} scene={self.scene_name!r} {self.state}>"


def _run_job(job: Job, results: queue.Queue) -> None:
    """Worker side: run ``job.fn`` unless cancelled and post the outcome. No bpy here."""
    outcome, value = "cancelled", None
    job.started = True
    if not job._cancel.is_set():
        try:
            value, outcome = job.fn(job._cancel.is_set), "done"
        except VoxGICancelled:
            outcome = "cancelled"
        except BaseException as error:  # noqa: BLE001 - handed to the main thread
            outcome, value = "failed", error
    job.finished_at = time.perf_counter()
    results.put((job, outcome, value))
    job._finished.set()


BACKGROUND_NICE = 10  # the worker threads' niceness over the main thread's (Linux)


def background_priority() -> None:
    """Lower the calling thread's CPU priority below the main thread's (Linux: a thread is a
    task of its own, ``setpriority`` on its id; elsewhere nothing). On two cores the worker's
    numpy (snapshots' geometry, BVH builds, cache layouts) ran beside the view's draws and
    made llvmpipe's raster threads of a draw wait for a core: a draw's image took 20–24 ms
    instead of 6–10 (docs/gi_pipeline.md "Worker threads below the main
    thread, steps timed to their rasters' end")."""
    if not sys.platform.startswith("linux"):
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(),
                       os.getpriority(os.PRIO_PROCESS, 0) + BACKGROUND_NICE)
    except (OSError, AttributeError):  # not permitted here: the thread keeps the process's
        return


def _work(inbox: queue.Queue, results: queue.Queue) -> None:
    background_priority()
    while (job := inbox.get()) is not None:
        _run_job(job, results)


class JobRunner:
    """The worker thread, its queues and the latest job of each scene."""

    def __init__(self):
        self._inbox: queue.Queue = queue.Queue()
        self._results: queue.Queue = queue.Queue()
        self._latest: dict[str, Job] = {}
        self._pending: list[Job] = []  # submitted, outcome not applied yet
        self.thread: threading.Thread | None = None

    @property
    def busy(self) -> bool:
        return bool(self._pending)

    @property
    def pending(self) -> list[Job]:
        return list(self._pending)

    def latest(self, scene_name: str) -> Job | None:
        return self._latest.get(scene_name)

    def submit(self, scene_name, fn, label, on_done, on_cancel, on_error, progress=None,
               finish_running: bool = False) -> Job:
        old = self._latest.get(scene_name)
        if old is not None and old.state == "running" and not (
                finish_running and old.started and not old.superseded):
            old.superseded = True
            old._cancel.set()
        job = Job(scene_name, fn, label, on_done, on_cancel, on_error, progress)
        self._latest[scene_name] = job
        self._pending.append(job)
        if self.thread is None:
            self.thread = threading.Thread(target=_work, args=(self._inbox, self._results),
                                           name="VoxGI engine worker", daemon=True)
            # busy from a job's submission until its outcome is applied (bakes.busy_thread)
            self.thread.voxgi_busy = lambda: self.busy
            self.thread.start()
        self._inbox.put(job)
        return job

    def cancel(self, scene_name: str, discard: bool) -> Job | None:
        job = self._latest.get(scene_name)
        if job is None or job.state != "running" or job.superseded:
            return None
        job.superseded = job.superseded or discard
        job._cancel.set()
        return job

    def cancel_all(self) -> None:
        for job in self._pending:
            job.superseded = True
            job._cancel.set()

    def drain(self) -> list[Job]:
        """Apply every outcome the worker has posted (main thread); returns those jobs."""
        applied = []
        while True:
            try:
                job, outcome, value = self._results.get_nowait()
            except queue.Empty:
                return applied
            self._pending.remove(job)
            _apply(job, outcome, value)
            applied.append(job)

    def shutdown(self, timeout: float) -> bool:
        """Cancel everything, stop the worker and wait for it; False if it is still running."""
        self.cancel_all()
        self._inbox.put(None)
        stopped = True
        if self.thread is not None:
            self.thread.join(timeout)
            stopped = not self.thread.is_alive()
        self.drain()
        return stopped


def _apply(job: Job, outcome: str, value) -> None:
    """Main thread: set the final state and run the job's callback (none if superseded)."""
    job.fn = None  # drop the snapshot it closes over
    if outcome == "failed" and not job.cancel_requested:
        job.state, job.error, callback, args = "failed", value, job.on_error, (value,)
    elif outcome == "done" and not job.cancel_requested:
        job.state, job.result, callback, args = "done", value, job.on_done, (value,)
    else:
        if outcome == "failed":  # failed while being cancelled: still worth a trace
            traceback.print_exception(value)
        job.state, callback, args = "cancelled", job.on_cancel, ()
    job.on_done = job.on_cancel = job.on_error = None
    if job.superseded:
        return
    if callback is None:
        if job.state == "failed":
            traceback.print_exception(job.error)
        return
    try:
        callback(*args)
    except Exception as error:  # noqa: BLE001 - a callback bug must not stop the drain
        traceback.print_exc()
        job.state, job.error = "failed", error


_runner: JobRunner | None = None


def _require_runner() -> JobRunner:
    if _runner is None:
        raise RuntimeError("VoxGI engine jobs are not available: the add-on is not registered")
    return _runner


def submit(scene_name: str, fn: Callable[[Callable[[], bool]], Any], *, label: str = "Job",
           on_done: Callable[[Any], None] | None = None,
           on_cancel: Callable[[], None] | None = None,
           on_error: Callable[[BaseException], None] | None = None,
           progress: Progress | None = None, finish_running: bool = False) -> Job:
    """Run ``fn(cancel)`` on the worker for the scene named ``scene_name``; main thread only.

    ``fn`` must not touch bpy; ``cancel()`` returns True once the job should stop (raise
    ``VoxGICancelled`` or return; the result is discarded either way). The callbacks run
    on the main thread when the outcome is applied. A running job of the same scene is
    superseded, or with ``finish_running`` left to finish and be applied (only a job of the
    scene still waiting to start is superseded: latest wins, nothing queues up). When
    ``runs_synchronously()`` the job is finished and applied on return (with progress lines
    for long jobs, see ``ProgressPrinter``).
    """
    runner = _require_runner()
    job = runner.submit(scene_name, fn, label, on_done, on_cancel, on_error, progress,
                        finish_running)
    if runs_synchronously():
        printer = ProgressPrinter(label)
        while not job.wait(0.1):
            printer.tick(progress)
        drain()
    else:
        _start_timer()
    return job


def cancel(scene_name: str, *, discard: bool = False) -> Job | None:
    """Ask the running job of a scene to stop; returns it, or None when nothing runs.

    discard : forget it silently (no ``on_cancel``), as when a newer request replaces it.
    """
    return None if _runner is None else _runner.cancel(scene_name, discard)


def cancel_all() -> None:
    """Cancel every job and drop their outcomes silently (file load)."""
    if _runner is not None:
        _runner.cancel_all()


def wait_idle(timeout: float | None = None) -> bool:
    """Block until every submitted job is finished, then ``drain()``; False on timeout."""
    deadline = None if timeout is None else time.perf_counter() + timeout
    while _runner is not None and _runner.busy:
        for job in _runner.pending:
            left = None if deadline is None else max(0.0, deadline - time.perf_counter())
            if not job.wait(left):
                drain()
                return False
        drain()
    return True


def running_job(scene_name: str) -> Job | None:
    """The scene's job while it runs (superseded ones excluded), else None."""
    job = None if _runner is None else _runner.latest(scene_name)
    return job if job is not None and job.state == "running" and not job.superseded else None


def latest_job(scene_name: str) -> Job | None:
    """The scene's most recent job in any state, or None."""
    return None if _runner is None else _runner.latest(scene_name)


def drain() -> list[Job]:
    """Apply the outcomes of finished jobs now (main thread); returns the jobs applied.

    What the timer does; tests and background scripts call it directly since timers do
    not fire without an event loop. Removes the timer once nothing runs.
    """
    if _runner is None:
        return []
    applied = _runner.drain()
    if applied:
        tag_sidebars()
    if not _runner.busy:
        _stop_timer()
        if _progress_shown:
            show_progress([])
    return applied


def _tick() -> float | None:
    """``bpy.app.timers`` callback: drain, refresh the panel and the progress display, stop
    when idle."""
    if _runner is None:
        return None
    try:
        _runner.drain()
    except Exception:  # noqa: BLE001 - a timer that raises is dropped by Blender
        traceback.print_exc()
    tag_sidebars()
    show_progress(_runner.pending)
    return TICK_SECONDS if _runner.busy else None


_progress_shown = False


def progress_text(job: Job) -> str:
    """What the status bar and the sidebar say about a running job."""
    progress = job.progress
    if job.cancel_requested:
        return f"VoxGI: cancelling {job.label.lower()}…"
    done = "" if progress is None else f" {progress.fraction * 100:.0f}%"
    what = "" if progress is None or not progress.text else f": {progress.text}"
    return f"VoxGI: {job.label}{done}{what} (Esc to cancel)"


def show_progress(pending: list[Job]) -> None:
    """The window manager's progress bar and the status-bar text for the first running job
    with a ``Progress``; both cleared once none runs. Interactive sessions only."""
    global _progress_shown
    jobs_with_progress = [j for j in pending if j.progress is not None and not j.superseded]
    # No window (background mode) or a closing one raises: there is nothing to show then.
    with contextlib.suppress(AttributeError, RuntimeError):
        for wm in bpy.data.window_managers:
            if jobs_with_progress:
                job = jobs_with_progress[0]
                if not _progress_shown:
                    wm.progress_begin(0.0, 1.0)
                wm.progress_update(job.progress.fraction)
            elif _progress_shown:
                wm.progress_end()
            for window in wm.windows:
                if window.workspace is not None:
                    window.workspace.status_text_set_internal(
                        progress_text(jobs_with_progress[0]) if jobs_with_progress else None)
    _progress_shown = bool(jobs_with_progress)


def timer_registered() -> bool:
    return bpy.app.timers.is_registered(_tick)


def _start_timer() -> None:
    if not timer_registered():
        # persistent: a file load must not strand a running job without its drain.
        bpy.app.timers.register(_tick, first_interval=TICK_SECONDS, persistent=True)


def _stop_timer() -> None:
    if timer_registered():
        bpy.app.timers.unregister(_tick)


@bpy.app.handlers.persistent
def _cancel_on_load(*_args) -> None:
    # Results belong to the file they were computed from: drop them silently.
    cancel_all()


classes = ()


def register() -> None:
    global _runner
    _runner = JobRunner()
    if _cancel_on_load not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(_cancel_on_load)


def unregister() -> None:
    """Timers first, then cancel every job and join the worker (at most ``JOIN_TIMEOUT``)."""
    global _runner
    _stop_timer()
    show_progress([])
    if _cancel_on_load in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_cancel_on_load)
    runner, _runner = _runner, None
    if runner is not None and not runner.shutdown(JOIN_TIMEOUT):
        print(f"VoxGI: the engine worker did not stop within {JOIN_TIMEOUT:g} s; "
              "it is a daemon thread and its result will be discarded")

"""A frame as a declared list of stages (docs/gi_pipeline.md "The frame's stages"), as
Filament's frame graph declares its passes: each ``Stage`` names the values it reads and the
values it writes, and says when it runs; ``run`` runs a list over a ``Frame`` whole (F12,
``render_preview``, probe previews) or, being a generator that yields where the stages yield,
a slice at a time (the viewport's draws). A feature is one more stage in a list, not one more
branch inside a shared function; ``check`` proves a list's order (every value read is given
or written by an earlier stage) without running it.

No GPU here: the stages' functions live beside the kernels they dispatch
(``gpu_preview.ACCURATE_STAGES``).
"""
from __future__ import annotations

import inspect
import time
from dataclasses import dataclass, field
from typing import Callable


def _always(frame) -> bool:
    return True


@dataclass(frozen=True)
class Stage:
    """name : its line in the render's timings ("" : none); reads, writes : the values it
    takes from the frame and the ones it returns (a dict with exactly those keys); run(frame)
    : a function or a generator function (yielding between its dispatches) doing the work;
    when(frame) : False leaves it out, its writes then taken from skipped(frame) (None each
    by default); slice_end : ``run`` yields after it (one of the viewport's steps ends)."""

    name: str
    reads: tuple[str, ...]
    writes: tuple[str, ...]
    run: Callable
    when: Callable = _always
    skipped: Callable | None = None
    slice_end: bool = True


@dataclass
class Frame:
    """One run of a stage list: the values given (``given`` their names: the request every
    stage may read) and written so far (name → value), and each stage's seconds under its
    name."""

    values: dict
    given: set = field(default_factory=set)
    timings: dict = field(default_factory=dict)

    def __getitem__(self, name: str):
        return self.values[name]


class _Reads:
    """What a stage's function sees of the frame: the given values and those it declares it
    reads or writes (anything else is a KeyError naming the stage: the list stays true)."""

    def __init__(self, frame: Frame, stage: Stage):
        self._frame, self._stage = frame, stage

    def __getitem__(self, name: str):
        stage = self._stage
        if name not in self._frame.given and name not in stage.reads and \
                name not in stage.writes:
            raise KeyError(f"stage {stage.name or stage.run.__name__!r} reads {name!r}, which "
                           "it does not declare")
        return self._frame.values[name]


def check(stages, given) -> None:
    """Raise ValueError unless every value a stage of ``stages`` reads is among ``given`` or
    written by a stage before it, and no two stages write the same value."""
    known = set(given)
    for stage in stages:
        missing = [name for name in stage.reads if name not in known]
        if missing:
            raise ValueError(f"stage {stage.name or stage.run.__name__!r} reads {missing}, "
                             "which nothing before it writes")
        again = known.intersection(stage.writes)
        if again:
            raise ValueError(f"stage {stage.name or stage.run.__name__!r} writes {sorted(again)} "
                             "again")
        known.update(stage.writes)


_RUNNING = [""]  # the name of the stage a ``run`` last entered (``running``)


def running() -> str:
    """The name of the stage a ``run`` last entered: where a viewport draw's step was (its
    traces name a long step by it)."""
    return _RUNNING[0]


def run(stages, frame: Frame):
    """Generator running ``stages`` in order over ``frame`` (yielding inside the stages and
    after each ``slice_end`` one); returns ``frame``. A stage that returns other values than
    it declares is an error (the list is the frame's documentation)."""
    for stage in stages:
        view = _Reads(frame, stage)
        if not stage.when(view):
            frame.values.update(stage.skipped(view) if stage.skipped is not None
                                else dict.fromkeys(stage.writes))
            continue
        _RUNNING[0] = stage.name or stage.run.__name__
        t0 = time.perf_counter()
        out = stage.run(view)
        if inspect.isgenerator(out):
            out = yield from out
        if set(out) != set(stage.writes):
            raise RuntimeError(f"stage {stage.name or stage.run.__name__!r} wrote {sorted(out)}, "
                               f"not {sorted(stage.writes)}")
        frame.values.update(out)
        if stage.name:
            frame.timings[stage.name] = frame.timings.get(stage.name, 0.0) + \
                time.perf_counter() - t0
        if stage.slice_end:
            yield
    return frame


def finish(steps):
    """Run a generator of steps (a stage list's ``run``, a kernel's dispatches, …) to its end:
    its return value (F12 and the other one-call renders)."""
    while True:
        try:
            next(steps)
        except StopIteration as end:
            return end.value

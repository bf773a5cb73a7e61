"""What ``render.viewport.view_draw`` uses of a ``RenderEngine``, for drawing the viewport
headless (tests/blender/test_viewport.py, tools/bench/bench_viewport_blender.py): bpy cannot make
a viewport engine in background mode. Its Python attributes (``voxgi_viewport``) persist
between draws as a real engine's do."""
from __future__ import annotations


class StandInEngine:
    """Counts ``tag_redraw`` calls and keeps every ``update_stats`` line (``stats``)."""

    def __init__(self):
        self.redraws, self.stats = 0, []

    def bind_display_space_shader(self, scene):
        """Nothing to bind: the tests and the benchmark draw into an offscreen buffer."""

    def unbind_display_space_shader(self):
        """Nothing was bound."""

    def tag_redraw(self):
        self.redraws += 1

    def update_stats(self, stats, info):
        self.stats.append(info)

"""bpy.ops.voxgi.voxelize: counts on the demo scene, and a clear message for each bad input."""
from __future__ import annotations

import bpy
import numpy as np
import pytest
import scenes


def _report(session, level=None):
    lines = session.scene_session(bpy.context.scene.name_full).last_report
    return [m for lvl, m in lines if level is None or lvl == level]


def test_voxelize_demo_scene_reports_each_cascade(voxgi, session):
    bpy.ops.voxgi.add_demo_scene()
    bpy.context.scene.voxgi.cascade_count = 2

    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}

    state = session.scene_session(bpy.context.scene.name_full)
    cascades = [m for m in _report(session, "INFO") if m.startswith("Cascade ")]
    assert len(cascades) == 2 and "voxels" in cascades[0] and "MB" in cascades[0]
    assert len(state.caches.cascade_stats) == 2
    assert state.caches.total_voxels > 0
    assert set(state.caches.caches) == {"Cornell Box", "Skinned Tube (modified)", "Rotating Sphere"}
    assert state.snapshot_summary["objects"] == 3
    assert "snapshot" in state.timings
    assert _report(session, "ERROR") == []


def test_empty_scene_is_an_error_not_a_crash(voxgi, session):
    with pytest.raises(RuntimeError):  # bpy.ops raises when the operator reports an ERROR
        bpy.ops.voxgi.voxelize()
    errors = _report(session, "ERROR")
    assert len(errors) == 1 and "no visible mesh" in errors[0]


def test_only_faceless_meshes_is_an_error_naming_them(voxgi, session):
    scenes.mesh_object("Wire", [(0, 0, 0), (1, 0, 0)], edges=[(0, 1)])
    with pytest.raises(RuntimeError):
        bpy.ops.voxgi.voxelize()
    assert "'Wire' has no faces" in _report(session, "ERROR")[0]


def test_mesh_without_faces_is_a_warning(voxgi, session):
    scenes.quad_object("Quad")
    scenes.mesh_object("Points", [(0, 0, 0), (1, 1, 1)])
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    assert any("'Points' has no faces" in m for m in _report(session, "WARNING"))


def test_zero_area_and_nan_triangles_are_dropped_and_counted(voxgi, session):
    vertices = [(0, 0, 0), (1, 0, 0), (0, 1, 0),      # a good triangle
                (2, 0, 0), (3, 0, 0), (4, 0, 0),      # collinear: zero area
                (5, 0, 0), (6, 0, 0), (5, 1, 0)]      # gets a NaN below
    obj = scenes.mesh_object("Broken", vertices, faces=[(0, 1, 2), (3, 4, 5), (6, 7, 8)])
    positions = np.array(vertices, dtype=np.float32)
    positions[7] = np.nan
    obj.data.vertices.foreach_set("co", positions.ravel())
    obj.data.update()

    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}

    dropped = [m for m in _report(session, "WARNING") if "dropped" in m]
    assert len(dropped) == 1 and "'Broken'" in dropped[0] and "dropped 2" in dropped[0]
    state = session.scene_session(bpy.context.scene.name_full)
    assert state.caches.dropped_triangles == {"Broken": 2}


def test_non_uniform_scale_is_a_warning(voxgi, session):
    scenes.quad_object("Stretched").scale = (1.0, 3.0, 1.0)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    assert any("Stretched" in m and "scale" in m for m in _report(session, "WARNING"))


def test_settings_defaults_and_limits(voxgi):
    settings = bpy.context.scene.voxgi
    assert (settings.span_mode, settings.memory_budget) == ("AUTO", 256)
    assert settings.base_span == pytest.approx(0.1)
    assert (settings.cascade_count, settings.grid_resolution) == (3, "64")
    settings.cascade_count = 99
    assert settings.cascade_count == 6
    settings.base_span = 0.0
    assert settings.base_span == pytest.approx(0.001)
    props = type(settings).bl_rna.properties
    assert props["base_span"].subtype == "DISTANCE" and props["base_span"].unit == "LENGTH"
    for name in ("span_mode", "memory_budget", "base_span", "cascade_count", "grid_resolution"):
        assert props[name].description


def test_mesh_too_large_for_a_span_is_skipped_with_a_warning(voxgi, session):
    scenes.quad_object("Big Quad", size=2.0)
    bpy.context.scene.voxgi.span_mode = "MANUAL"
    bpy.context.scene.voxgi.base_span = 0.0015  # 2 m / 1.5 mm > 1024 voxels per axis
    bpy.context.scene.voxgi.cascade_count = 1
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    skipped = [m for m in _report(session, "WARNING") if "skipped" in m]
    assert len(skipped) == 1 and "Big Quad" in skipped[0] and "0.0015" in skipped[0]

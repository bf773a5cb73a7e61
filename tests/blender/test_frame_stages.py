"""The Accurate frame as one declared list of stages (``render.frame``,
``gpu_preview.ACCURATE_STAGES``; docs/gi_pipeline.md "The frame's stages"): the list's order is
checked without running it, a stage can read and write only what it declares, and F12 reports
the stages it ran under their names, in the list's order.
"""
import bpy
import gi_scenes
import pytest

REQUEST = ("snapshot", "scene", "width", "height", "light_samples", "gi_stride", "settings",
           "glossy_indirect", "filter_width", "gather_hook", "raster", "cache_source",
           "camera_tris", "only", "on_gpu", "batch", "world_glossy")


def test_the_accurate_list_reads_only_what_is_given_or_written_before(voxgi):
    from voxgi.render import frame, gpu_preview

    frame.check(gpu_preview.ACCURATE_STAGES, REQUEST)
    names = [stage.name for stage in gpu_preview.ACCURATE_STAGES]
    assert names.index("radiance cache") < names.index("diffuse+ao gather (GPU)") < \
        names.index("direct (GPU)") < names.index("sub-pixel passes (GPU)")
    # a list whose stage reads what nothing before it writes is refused before it runs
    reordered = list(gpu_preview.ACCURATE_STAGES)
    reordered.insert(1, reordered.pop(names.index("direct (GPU)")))
    with pytest.raises(ValueError, match="direct"):
        frame.check(reordered, REQUEST)


def test_a_stage_reads_and_writes_only_what_it_declares(voxgi):
    from voxgi.render import frame

    def finish(stages, values):
        run = frame.run(stages, frame.Frame(values, given={"x"}))
        while True:
            try:
                next(run)
            except StopIteration as end:
                return end.value

    double = frame.Stage("double", (), ("y",), lambda f: {"y": 2 * f["x"]})
    peek = frame.Stage("peek", (), ("z",), lambda f: {"z": f["y"]})  # y undeclared
    with pytest.raises(KeyError, match="peek.*'y'"):
        finish((double, peek), {"x": 3})
    sloppy = frame.Stage("sloppy", (), ("y",), lambda f: {"y": 1, "w": 2})
    with pytest.raises(RuntimeError, match="sloppy"):
        finish((sloppy,), {"x": 3})
    skipped = frame.Stage("later", ("y",), ("z",), lambda f: {"z": f["y"]},
                          when=lambda f: f["x"] > 5, skipped=lambda f: {"z": -1})
    done = finish((double, skipped), {"x": 3})
    assert done["y"] == 6 and done["z"] == -1 and "later" not in done.timings
    assert "double" in done.timings


def test_f12_reports_the_stages_it_ran_in_the_lists_order(voxgi):
    from voxgi.blender.session import scene_session
    from voxgi.render import gpu_preview
    from voxgi.render.pipeline import render_scene_passes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gi_scenes.build(sorted(gi_scenes.SCENES)[0], scene)
    scene.voxgi.bounce_source = "MANUAL"
    scene.voxgi.bounces = 2  # with the radiance cache
    render_scene_passes(bpy.context, scene, None, 40, 30)
    assert scene_session(scene.name_full).tracer_used == "GPU"
    timings = scene_session(scene.name_full).gi_timings
    order = [stage.name for stage in gpu_preview.ACCURATE_STAGES if stage.name]
    ran = [name for name in timings if name in order]
    assert ran == [name for name in order if name in ran]  # in the list's order
    assert {"visibility (GPU)", "radiance cache", "diffuse+ao gather (GPU)", "direct (GPU)",
            "sub-pixel passes (GPU)", "finish"} <= set(ran), ran

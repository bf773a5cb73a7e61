"""One GPU scene per snapshot (issue 17, point 6; render/gpu_scene.py): a second render of an
unchanged scene uploads nothing, a change re-uploads only the part it touches, the passes are
those of a scene built from nothing, and a file load leaves no stale tables behind.
"""
from __future__ import annotations

import bpy
import light_scenes
import numpy as np
import pytest

WIDTH, HEIGHT = 40, 30


def gpu_ready():
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    assert ready, f"no GPU context: {why}"  # llvmpipe gives one everywhere CI runs


def snapshot_now():
    from voxgi.blender.snapshot import snapshot_or_error

    bpy.context.view_layer.update()
    return snapshot_or_error(bpy.context, None)[0]


def render(snapshot, gpu_scene, width=WIDTH, height=HEIGHT):
    """The Accurate GPU passes of ``snapshot`` (the scene's settings) drawn from ``gpu_scene``."""
    from voxgi.blender.settings import cone_settings, trace_options
    from voxgi.render.gpu_preview import render_passes_gpu

    settings = bpy.context.scene.voxgi
    assert settings.quality == "ACCURATE"
    passes, _ = render_passes_gpu(snapshot, None, width, height, cone_settings(settings),
                                  gpu_scene=gpu_scene,
                                  **trace_options(settings, width, height, snapshot.frame))
    return {name: np.asarray(image, np.float64) for name, image in passes.items()}


def fresh(snapshot, width=WIDTH, height=HEIGHT):
    """The passes of ``snapshot`` from a scene that shares nothing (its own BVH too)."""
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene

    return render(snapshot, GPUScene(bvh=GPUBVH()), width, height)


def assert_same_passes(ours, theirs):
    for name, image in theirs.items():
        scale = max(float(np.abs(image).max()), 1e-6)
        assert np.abs(ours[name] - image).max() <= 1e-5 * scale, name


def largest_change(before, after):
    return max(float(np.abs(after[n] - before[n]).sum() / max(np.abs(before[n]).sum(), 1e-12))
               for n in before)


def test_an_unchanged_scene_uploads_nothing_the_second_time(voxgi):
    """The room with a spot, an emissive panel and a glowing sphere: the first render uploads
    every part; a second one, from a new snapshot of the same scene, uploads 0 bytes and gives
    the same passes."""
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene

    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    scene = GPUScene(bvh=GPUBVH())
    first = render(snapshot_now(), scene)
    assert {"bvh", "materials", "lights", "emitters"} <= set(scene.uploaded)
    assert scene.uploaded_bytes > 0
    assert len(scene.lights) == 2 and scene.lights[-1].type == "EMITTERS"  # spot + emitters
    second = render(snapshot_now(), scene)
    assert scene.uploaded == {} and scene.uploaded_bytes == 0
    assert_same_passes(second, first)


def _move_spot():
    bpy.data.objects["Spot"].location.x -= 1.5


def _move_box():
    bpy.data.objects["Box"].location.x -= 0.6


def _recolour_red():
    bpy.data.materials["Red"].node_tree.nodes["Principled BSDF"] \
        .inputs["Base Color"].default_value = (0.1, 0.6, 0.2, 1.0)


@pytest.mark.parametrize("change, parts", [
    (_move_spot, {"lights"}),       # a lamp: its tables only
    (_move_box, {"bvh"}),           # a non-emissive object: the BVH (the emitters stay)
    (_recolour_red, {"materials"}),  # a material's colour: the materials texture
], ids=["lamp moved", "object moved", "material recoloured"])
def test_a_change_uploads_only_what_it_touches(voxgi, change, parts):
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene

    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    scene = GPUScene(bvh=GPUBVH())
    before = render(snapshot_now(), scene)
    change()
    snapshot = snapshot_now()
    after = render(snapshot, scene)
    assert set(scene.uploaded) == parts, scene.uploaded
    assert largest_change(before, after) > 0.01, "the change did not show in the passes"
    assert_same_passes(after, fresh(snapshot))


def test_a_world_edit_uploads_the_world_map_only(voxgi):
    """The uniform sky + sun courtyard with another sky colour: the world map (and its
    importance table) alone goes up again."""
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene

    gpu_ready()
    light_scenes.build("sky_courtyard", bpy.context.scene)
    scene = GPUScene(bvh=GPUBVH())
    before = render(snapshot_now(), scene)
    background = bpy.context.scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.8, 0.5, 0.3, 1.0)
    snapshot = snapshot_now()
    after = render(snapshot, scene)
    assert set(scene.uploaded) == {"world"}, scene.uploaded
    assert largest_change(before, after) > 0.01
    assert_same_passes(after, fresh(snapshot))


def test_f12_after_a_file_load_draws_the_new_files_scene(voxgi, tmp_path):
    """F12 of the emissive room, a factory reset (the load drops the session's scene), then F12
    of the HDRI courtyard: its passes are those of a scene built from nothing."""
    from test_final_renders import HEIGHT as F12_HEIGHT
    from test_final_renders import WIDTH as F12_WIDTH
    from test_final_renders import f12

    from voxgi.blender.settings import pixel_filter_width
    from voxgi.render import gpu_scene
    from voxgi.voxgi_addon.preview.film import snapshot_combined

    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    f12(bpy.context.scene, tmp_path / "room.exr")
    assert gpu_scene.peek_scene() is not None
    assert [light.type for light in gpu_scene.peek_scene().lights] == ["SPOT", "EMITTERS"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert gpu_scene.peek_scene() is None, "the file load kept the last file's GPU scene"

    scene = bpy.context.scene
    light_scenes.build("hdri_courtyard", scene)
    ours = f12(scene, tmp_path / "courtyard.exr")
    assert [light.type for light in gpu_scene.peek_scene().lights] == ["WORLD"]
    snapshot = snapshot_now()
    theirs = fresh(snapshot, F12_WIDTH, F12_HEIGHT)
    # F12's Combined shows the world behind the geometry (the film)
    theirs["Combined"] = snapshot_combined(snapshot, theirs, pixel_filter_width(scene))
    assert theirs["Diffuse Direct"].mean() > 0.01
    for name in ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct"):
        a, b = (np.asarray(p[name])[..., :3] for p in (ours, theirs))
        error = np.abs(a - b).sum() / np.abs(b).sum()
        assert error < 1e-3, (name, error)


def test_the_passes_g_buffers_share_one_vertex_batch(voxgi, monkeypatch):
    """The anti-aliased preview rasterizes several G-buffers — a G-buffer per sub-pixel pass
    where the image is too large for one raster to draw several (``gpu_preview.supersampling``
    1, as at 1920 × 1080): the triangles' vertex batch is built once for all of a render's
    G-buffers (gbuffer.vertex_batch), and the passes equal those of a batch built for every
    G-buffer (as before)."""
    from voxgi.render import gbuffer, gpu_preview

    gpu_ready()
    monkeypatch.setattr(gpu_preview, "supersampling", lambda *a: 1)
    light_scenes.build("emissive_room", bpy.context.scene)
    built = []
    original = gbuffer._new_batch

    def counted(*args):
        built.append(1)
        return original(*args)

    monkeypatch.setattr(gbuffer, "_new_batch", counted)
    snapshot = snapshot_now()
    shared = fresh(snapshot)
    assert len(built) == 1
    monkeypatch.setattr(gpu_preview, "vertex_batch", lambda *args: None)  # one per G-buffer
    every = fresh(snapshot)
    assert len(built) > 3
    assert_same_passes(shared, every)


def test_the_other_parts_go_in_while_the_bvh_builds(voxgi, monkeypatch):
    """``GPUScene.prepare``'s on_tables (the viewport, docs/gi_pipeline.md "Entering Rendered
    mode"): the plan comes with every part but the BVH, whose build is held here; its upload
    sends those parts a step each, then steps that send nothing while the BVH builds, then the
    BVH's three textures; the scene is then the plan's and renders as one built in one go.
    (A texture a step, as a large scene's: ``PART_BYTES`` 0.)"""
    import threading

    from voxgi.render import gpu_bvh, gpu_scene

    monkeypatch.setattr(gpu_scene, "PART_BYTES", 0)
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import WAITING, GPUScene
    from voxgi.render.gpu_shaders import counters

    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    snapshot = snapshot_now()
    release = threading.Event()
    pack = GPUBVH.pack

    def held(self, tris):
        assert release.wait(60.0)
        return pack(self, tris)

    monkeypatch.setattr(gpu_bvh.GPUBVH, "pack", held)
    scene = GPUScene(bvh=GPUBVH())
    plans = []
    done = threading.Event()
    worker = threading.Thread(target=lambda: (scene.prepare(snapshot, on_tables=plans.append),
                                              done.set()))
    worker.start()
    try:
        for _ in range(600):
            if plans:
                break
            done.wait(0.05)
        assert plans and not done.is_set(), "the plan came only with its BVH"
        plan = plans[0]
        assert plan.lights and not plan.bvh_ready.is_set()
        steps = scene.upload_steps(plan)
        before = []
        for _ in range(50):  # the other parts, one per step, then nothing while it builds
            mark = counters.mark()
            step = next(steps)
            sent = counters.since(mark)[1]
            if step == WAITING:
                assert sent == []
                break
            assert len(sent) == 1
            before += sent
        assert before and not any(part.startswith("bvh") for part in before)
        assert next(steps) == WAITING  # still building: still nothing
    finally:
        release.set()
        worker.join(60.0)
    assert done.is_set()
    after = []
    for _ in range(50):
        mark = counters.mark()
        try:
            next(steps)
        except StopIteration:
            after += counters.since(mark)[1]
            break
        sent = counters.since(mark)[1]
        assert len(sent) <= 1
        after += sent
    assert after == ["bvh nodes", "bvh triangles", "bvh normals"]
    assert scene.keys == plan.keys and scene.tris is plan.tris
    assert_same_passes(render(snapshot, scene), fresh(snapshot))


def test_small_parts_go_in_together_within_part_bytes(voxgi, monkeypatch):
    """``gpu_scene.PART_BYTES``: consecutive scene parts go in one upload step (a view_draw's
    one scene part) while their bytes stay within it — the emissive room's tables in fewer
    steps than a texture a step — no step sends more than that unless one texture alone is
    larger, each step counts one part, and the scene renders as one sent a texture a step."""
    from voxgi.render import gpu_bvh, gpu_scene
    from voxgi.render.gpu_bvh import GPUBVH
    from voxgi.render.gpu_scene import GPUScene
    from voxgi.render.gpu_shaders import counters

    gpu_ready()
    light_scenes.build("emissive_room", bpy.context.scene)
    snapshot = snapshot_now()
    made = []
    default = gpu_scene.PART_BYTES

    def counted(module, name):
        original = getattr(module, name)

        def make(*args, **kwargs):
            texture = original(*args, **kwargs)
            made.append(texture.width * texture.height * (8 if texture.format == "RGBA16F"
                                                          else 16))
            return texture
        monkeypatch.setattr(module, name, make)

    for module, name in ((gpu_scene, "float_texture"), (gpu_bvh, "float_texture"),
                         (gpu_scene, "principled_materials_texture")):
        counted(module, name)

    def sent_in_steps(part_bytes):
        monkeypatch.setattr(gpu_scene, "PART_BYTES", part_bytes)
        scene = GPUScene(bvh=GPUBVH())
        plan = scene.prepare(snapshot)
        assert plan.bvh_ready.wait(60.0)
        steps, sizes = scene.upload_steps(plan), []
        while True:
            mark = counters.mark()
            made.clear()
            try:
                next(steps)
                ended = False
            except StopIteration:
                ended = True
            parts = counters.since(mark)[1]
            assert len(parts) <= 1, parts
            if made:
                assert len(parts) == 1, (parts, made)  # one counted part a step that sends
                sizes.append(list(made))
            if ended:
                return scene, sizes

    apart, one_by_one = sent_in_steps(0)
    together, grouped = sent_in_steps(default)
    assert len(grouped) < len(one_by_one), (grouped, one_by_one)
    assert all(sum(step) <= default or len(step) == 1 for step in grouped), grouped
    assert sorted(b for step in grouped for b in step) == \
        sorted(b for step in one_by_one for b in step)  # the same textures
    assert together.keys == apart.keys
    assert_same_passes(render(snapshot, together), render(snapshot, apart))

"""Debug views (render/debug_draw.py) drawn into a GPUOffScreen from a fixed view: a red cube's
voxels come back red where the cube is and the background elsewhere, in every colour mode, at
octree levels and with the cascade bounds; batches are rebuilt only when results change and
gpu.state is restored."""
from __future__ import annotations

import bpy
import gpu
import numpy as np
import pytest
import scenes

SIZE = 64
BACKGROUND = (0.0, 0.0, 0.25, 1.0)


def look_at(eye, target=(0.0, 0.0, 0.0)):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = eye - target
    z /= np.linalg.norm(z)
    x = np.cross([0, 0, 1.0], z)
    x /= np.linalg.norm(x)
    world = np.eye(4)
    world[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
    world[:3, 3] = eye
    return np.linalg.inv(world)


def perspective(fov=0.8, near=0.1, far=100.0):
    p = np.zeros((4, 4))
    p[0, 0] = p[1, 1] = 1 / np.tan(fov / 2)
    p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1
    return p


VIEW = look_at((3.0, -4.0, 3.0))
WINDOW = perspective()


@pytest.fixture
def red_cube_state(voxgi):
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.gpu_context import ensure_gpu_context

    scene = bpy.context.scene
    h = 0.5
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    cube = scenes.mesh_object("Red Cube", corners, faces)
    cube.data.materials.append(scenes.principled("Red", (0.9, 0.05, 0.05)))
    light = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    light.data.energy = 3.0
    scenes.link(light)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scenes.link(camera)  # at the origin: the cascades are centred on the cube
    scene.camera = camera
    scene.voxgi.base_span, scene.voxgi.cascade_count, scene.voxgi.grid_resolution = 0.125, 2, "32"
    scene.voxgi.view_ahead = 0.0
    live = live_gi(scene.name_full)
    live.update(scene, bpy.context.evaluated_depsgraph_get())
    assert live.staged is not None, live.error
    ready, why = ensure_gpu_context()
    assert ready, why
    return scene, live.staged.state


def draw(drawer, state, settings):
    from voxgi.render.debug_draw import draw_debug, eye_of
    from voxgi.render.gpu_tracer import read_texture

    offscreen = gpu.types.GPUOffScreen(SIZE, SIZE, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=BACKGROUND, depth=1.0)
            before = (gpu.state.blend_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get())
            count = draw_debug(drawer, state, settings, WINDOW @ VIEW, eye_of(VIEW, WINDOW))
            after = (gpu.state.blend_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get())
        assert before == after  # gpu.state restored
        return count, np.flipud(read_texture(offscreen.texture_color))
    finally:
        offscreen.free()


def cube_mask():
    """Pixels the unit cube covers from VIEW, by projecting a dense sample of its surface."""
    g = np.linspace(-0.5, 0.5, 60)
    a, b = np.meshgrid(g, g)
    pts = []
    for axis in range(3):
        for side in (-0.5, 0.5):
            p = np.zeros((a.size, 3))
            p[:, axis] = side
            p[:, (axis + 1) % 3], p[:, (axis + 2) % 3] = a.ravel(), b.ravel()
            pts.append(p)
    clip = np.c_[np.concatenate(pts), np.ones(6 * a.size)] @ (WINDOW @ VIEW).T
    ndc = clip[:, :2] / clip[:, 3:]
    px = np.floor((ndc[:, 0] + 1) / 2 * SIZE).astype(int)
    py = SIZE - 1 - np.floor((ndc[:, 1] + 1) / 2 * SIZE).astype(int)
    mask = np.zeros((SIZE, SIZE), bool)
    mask[py, px] = True
    return mask


def settings(**kw):
    base = dict(debug_view="VOXELS", debug_cascade=0, debug_level=0, debug_colour="ALBEDO",
                show_bounds=False)
    return type("Settings", (), {**base, **kw})()


def test_voxels_of_a_red_cube_come_back_red_where_the_cube_is(red_cube_state):
    from voxgi.render.debug_draw import DebugDrawer

    _, state = red_cube_state
    drawer = DebugDrawer()
    count, image = draw(drawer, state, settings())
    assert count == state.cascades[0].voxel_count > 0
    cube = cube_mask()
    drawn = np.any(np.abs(image - BACKGROUND) > 1e-3, axis=-1)
    assert drawn[cube].mean() > 0.9 and drawn[~cube].mean() < 0.08  # voxels are ≥ the cube
    rgb = image[drawn][:, :3]
    assert (rgb[:, 0] > 4 * rgb[:, 1]).all() and (rgb[:, 0] > 0.45).all()  # red, shaded
    assert np.allclose(image[~drawn], BACKGROUND)
    print(f"cube pixels drawn {drawn[cube].mean():.3f}, outside drawn {drawn[~cube].mean():.3f}")

    # The same results and choice: nothing rebuilt. Another cascade: rebuilt once.
    draw(drawer, state, settings())
    assert drawer.builds == 1
    count1, _ = draw(drawer, state, settings(debug_cascade=1))
    assert drawer.builds == 2 and count1 == state.cascades[1].voxel_count


@pytest.mark.parametrize("mode", ["NORMAL", "OCCLUSION", "LIGHT"])
def test_colour_modes(red_cube_state, mode):
    from voxgi.render.debug_draw import DebugDrawer

    _, state = red_cube_state
    _, image = draw(DebugDrawer(), state, settings(debug_colour=mode))
    drawn = np.any(np.abs(image - BACKGROUND) > 1e-3, axis=-1)
    rgb = image[drawn][:, :3]
    assert drawn[cube_mask()].mean() > 0.9
    if mode == "OCCLUSION":  # leaves are full: grey
        assert np.allclose(rgb[:, 0], rgb[:, 1], atol=1e-5) and (rgb[:, 0] > 0.5).all()
    elif mode == "NORMAL":  # three faces seen, three normal colours (0.5 + 0.5·n, shaded)
        colours = np.unique(np.round(rgb / rgb.max(axis=1, keepdims=True), 1), axis=0)
        assert len(colours) >= 3 and not (rgb[:, 0] > 4 * rgb[:, 1]).all()
    else:  # injected sunlight on a red surface: red where lit, black where not
        lit = rgb.max(axis=1) > 0.05
        assert lit.mean() > 0.2 and (rgb[lit, 0] > 2 * rgb[lit, 1]).all()


def test_octree_levels_and_cascade_bounds(red_cube_state):
    from voxgi.render.debug_draw import BOUND_COLOURS, DebugDrawer

    _, state = red_cube_state
    octree = state.octree
    leaf = octree.cascade_levels[0]
    drawer = DebugDrawer()
    fine_count, fine = draw(drawer, state, settings(debug_view="OCTREE", debug_level=leaf))
    coarse_count, coarse = draw(drawer, state, settings(debug_view="OCTREE", debug_level=leaf - 2))
    assert fine_count == octree.levels[leaf].node_count and 0 < coarse_count < fine_count
    covered = [np.any(np.abs(img - BACKGROUND) > 1e-3, axis=-1) for img in (fine, coarse)]
    assert covered[1].sum() > covered[0].sum() >= 0.9 * cube_mask().sum()  # bigger nodes

    _, bounds = draw(drawer, state, settings(debug_view="NONE", show_bounds=True))
    drawn = np.any(np.abs(bounds - BACKGROUND) > 1e-3, axis=-1)
    assert 0 < drawn.mean() < 0.2  # thin lines, no cubes
    lines = bounds[drawn][:, :3]
    for cascade in range(len(state.grids)):  # each cascade's box in its colour
        assert np.any(np.all(np.abs(lines - BOUND_COLOURS[cascade][:3]) < 0.01, axis=1)), cascade


class Instanced:
    """Counts the instances of every cube draw (``debug_draw.draw_instances``)."""

    def __init__(self, monkeypatch):
        import voxgi.render.debug_draw as debug_draw

        self.calls: list[int] = []
        original = debug_draw.draw_instances

        def counted(batch, shader, start, count):
            self.calls.append(count)
            original(batch, shader, start, count)
        monkeypatch.setattr(debug_draw, "draw_instances", counted)

    def take(self) -> list[int]:
        calls, self.calls = self.calls, []
        return calls


def sliced_draw(drawer, state, chosen, view=VIEW, depth=1.0):
    """``draw_debug`` into a fresh offscreen cleared to ``depth``: (image, redraw asked)."""
    from voxgi.render.debug_draw import draw_debug, eye_of
    from voxgi.render.gpu_tracer import read_texture

    asked = []
    offscreen = gpu.types.GPUOffScreen(SIZE, SIZE, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=BACKGROUND, depth=depth)
            draw_debug(drawer, state, chosen, WINDOW @ view, eye_of(view, WINDOW),
                       redraw=lambda: asked.append(1))
        return np.flipud(read_texture(offscreen.texture_color)), bool(asked)
    finally:
        offscreen.free()


def test_cubes_are_drawn_a_slice_per_draw_and_kept_for_an_unchanged_view(red_cube_state,
                                                                         monkeypatch):
    """Issue 19 point 3: each draw issues at most one slice of instances (counted, not timed),
    asks for a redraw until all are in, shows the one-batch image then, and an unchanged view
    draws no cube again; a new view starts over."""
    from voxgi.render.debug_draw import DebugDrawer

    _, state = red_cube_state
    whole = DebugDrawer()
    whole.fixed_slice = 1 << 30  # every cube in one draw: the image before slicing
    instanced = Instanced(monkeypatch)
    one_batch, asked = sliced_draw(whole, state, settings())
    count = state.cascades[0].voxel_count
    assert instanced.take() == [count] and not asked

    drawer = DebugDrawer()
    drawer.fixed_slice = -(-count // 6)
    images, slices = [], []
    while True:
        image, asked = sliced_draw(drawer, state, settings())
        images.append(image)
        slices.append(instanced.take())
        if not asked:
            break
        assert len(images) < 20, "the slices never completed"
    assert len(images) == 6 and all(len(s) == 1 and s[0] <= drawer.fixed_slice for s in slices)
    assert sum(s[0] for s in slices) == count
    drawn = [np.any(np.abs(img - BACKGROUND) > 1e-3, axis=-1).sum() for img in images]
    print("pixels drawn per draw", drawn)
    assert 0 < drawn[0] < drawn[-1] and drawn == sorted(drawn)  # the cubes fill in
    assert np.array_equal(images[-1], one_batch)

    # unchanged: the kept layer, no cube drawn
    again, asked = sliced_draw(drawer, state, settings())
    assert instanced.take() == [] and not asked and np.array_equal(again, one_batch)
    # the view's own depth still hides cubes behind it (the layer carries its depth)
    hidden, _ = sliced_draw(drawer, state, settings(), depth=0.0)
    assert instanced.take() == [] and np.allclose(hidden, BACKGROUND)
    # a new view starts over with one slice, and shows it on that very draw
    other = look_at((-3.0, -4.0, 2.0))
    moved, asked = sliced_draw(drawer, state, settings(), view=other)
    assert instanced.take() == [drawer.fixed_slice] and asked
    assert np.any(np.abs(moved - BACKGROUND) > 1e-3)

"""Emission Color per texel (issue 18 point 2, issue 22 point 3): what the camera sees of a
material with an emission texture (``scene.textures.primary_base`` / ``texel_emission``, the
Combined pass's emission term) and the emissive triangles as a light (``gi.emitters``: a
textured emitter is split into pieces, each emitting the texture's mean over it)."""
import numpy as np

from voxgi.voxgi_addon.gi.conetrace import ConeSettings
from voxgi.voxgi_addon.gi.emitters import emitter_light, subdivision
from voxgi.voxgi_addon.preview.passes import material_table, render_passes
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import (
    CameraData,
    MaterialData,
    MeshData,
    ObjectData,
    SceneSnapshot,
    TextureData,
)

RED, BLUE = np.array([1.0, 0.1, 0.05]), np.array([0.05, 0.2, 1.0])
STRENGTH = 4.0


def two_colour_pixels(size=8):
    """Left half (u < 0.5) red, right half blue."""
    out = np.zeros((size, size, 3), np.float32)
    out[:, : size // 2] = RED
    out[:, size // 2:] = BLUE
    return out


def panel_snapshot(textured=True):
    """A 2 × 2 m panel at z = 1 facing down (emission per texel, or the texture's mean) over a
    grey floor at z = 0, seen from the front and above (an orthographic camera)."""
    panel = np.array([[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], np.float32)
    floor = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], np.float32)
    quad = np.array([[0, 2, 1], [0, 3, 2]], np.int32)  # facing −z
    up = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    meshes = {"panel": MeshData("panel", panel, quad, np.zeros(2, np.int32), uvs=uv[quad]),
              "floor": MeshData("floor", floor, up, np.ones(2, np.int32), uvs=uv[up])}
    pixels = two_colour_pixels()
    mean = pixels.reshape(-1, 3).mean(axis=0)
    glow = MaterialData("glow", np.zeros(3, np.float32), roughness=1.0, specular=0.0,
                        emission=(mean * STRENGTH).astype(np.float32),
                        emission_texture=0 if textured else -1, emission_strength=STRENGTH)
    grey = MaterialData("grey", np.full(3, 0.5, np.float32), roughness=1.0, specular=0.0)
    eye, target = np.array([0.0, -7.0, 5.0]), np.array([0.0, 0.0, 0.3])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    world = np.eye(4)
    world[:3, 0], world[:3, 1], world[:3, 2], world[:3, 3] = \
        right, np.cross(right, forward), -forward, eye
    camera = CameraData("cam", world, np.eye(4), (32, 24), type="ORTHO", ortho_scale=7.0,
                        clip_start=0.1, clip_end=30.0)
    texture = TextureData("two colours", pixels, interpolation="Closest", extension="EXTEND",
                          key="two colours")
    return SceneSnapshot(meshes=meshes, materials=[glow, grey],
                         objects=[ObjectData("panel", "panel", np.eye(4)),
                                  ObjectData("floor", "floor", np.eye(4))],
                         camera=camera, textures=(texture,))


def test_subdivision_tiles_the_triangle():
    for level in range(4):
        pieces = subdivision(level)
        assert pieces.shape == (4 ** level, 3, 3)
        np.testing.assert_allclose(pieces.sum(axis=-1), 1.0)
        corners = pieces[..., 1:]  # (b1, b2) in the unit right triangle: areas sum to 1/2
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        np.testing.assert_allclose(area, 0.5 / 4 ** level)


def test_textured_emitters_emit_each_half_its_colour():
    snapshot = panel_snapshot()
    tris = world_triangles(snapshot)
    light = emitter_light(tris, material_table(snapshot)[3])
    assert len(light.corners) > 2  # split
    centroid = light.corners.mean(axis=1)
    left, right = centroid[:, 0] < -0.1, centroid[:, 0] > 0.1
    # pieces inside one half emit that half's colour × the strength
    inside_left = left & (light.corners[..., 0].max(axis=1) <= 0.0)
    inside_right = right & (light.corners[..., 0].min(axis=1) >= 0.0)
    assert inside_left.sum() > 4 and inside_right.sum() > 4
    np.testing.assert_allclose(light.radiance[inside_left], np.tile(RED * STRENGTH, (inside_left.sum(), 1)),
                               rtol=2e-3)
    np.testing.assert_allclose(light.radiance[inside_right],
                               np.tile(BLUE * STRENGTH, (inside_right.sum(), 1)), rtol=2e-3)
    # the pieces' power is the panel's: area × the texture's mean × the strength
    power = (light.area[:, None] * light.radiance).sum(axis=0)
    np.testing.assert_allclose(power, 4.0 * snapshot.materials[0].emission, rtol=0.01)


def test_the_floor_under_each_half_takes_its_colour_and_the_camera_sees_the_texels():
    from voxgi.voxgi_addon.scene.raycast import primary_visibility

    cones = ConeSettings()
    snapshot = panel_snapshot(True)
    textured, _ = render_passes(snapshot, None, 32, 24, cones, light_samples=4, filter_width=0.0)
    mean, _ = render_passes(panel_snapshot(False), None, 32, 24, cones, light_samples=4,
                            filter_width=0.0)
    seen = primary_visibility(world_triangles(snapshot), snapshot.camera, 32, 24)
    x = seen.position[..., 0]
    floor = seen.hit & (seen.material == 1) & (seen.position[..., 1] < 1.0)
    left, right = floor & (x < -0.3) & (x > -1.5), floor & (x > 0.3) & (x < 1.5)
    assert left.sum() > 5 and right.sum() > 5

    def redness(passes, where):
        light = passes["Diffuse Direct"][where]
        return light[:, 0].mean() / light[:, 2].mean()

    # the red half lights the floor under it redder; the mean lights both sides alike
    assert redness(textured, left) > 1.5 * redness(textured, right)
    assert abs(redness(mean, left) / redness(mean, right) - 1.0) < 0.1
    # the same light on the floor in all
    np.testing.assert_allclose(textured["Diffuse Direct"][floor].sum(axis=0),
                               mean["Diffuse Direct"][floor].sum(axis=0), rtol=0.05)
    # what the camera sees of the panel: each half its texels × the strength, as Combined
    panel = seen.hit & (seen.material == 0)
    px = seen.position[..., 0]
    seen_left, seen_right = panel & (px < -0.1), panel & (px > 0.1)
    assert seen_left.sum() > 3 and seen_right.sum() > 3
    np.testing.assert_allclose(textured["Combined"][seen_left],
                               np.tile(RED * STRENGTH, (seen_left.sum(), 1)), rtol=1e-3)
    np.testing.assert_allclose(textured["Combined"][seen_right],
                               np.tile(BLUE * STRENGTH, (seen_right.sum(), 1)), rtol=1e-3)
    np.testing.assert_allclose(mean["Combined"][seen_left],
                               np.tile(snapshot.materials[0].emission, (seen_left.sum(), 1)),
                               rtol=1e-3)


def test_packed_emission_round_trips_within_its_precision():
    from voxgi.voxgi_addon.scene.textures import EMISSION_MAX, pack_emission, unpack_emission

    rng = np.random.default_rng(5)
    values = rng.random((2000, 3)) * np.exp2(rng.integers(-12, 15, (2000, 1)))
    values[:5] = [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0.5], [EMISSION_MAX, 1, 0], [4.0, 0.4, 0.2]]
    packed = pack_emission(values)
    assert (packed >= 2.0).all() and np.isfinite(packed).all()
    back = unpack_emission(packed)
    brightest = values.max(axis=1, keepdims=True)
    assert (np.abs(back - values) <= brightest * 2.0 ** -8 + 1e-12).all()
    assert (back[0] == 0).all()
    np.testing.assert_allclose(unpack_emission(np.float32([0.0, 1.0])), 0.0)  # no emission texture


def test_the_panels_voxels_glow_with_each_halfs_colour():
    """Fast quality's voxels take the emission of the emitters' pieces (light_injection): the
    panel's voxels over its left half glow red, over its right half blue; the mean's glow
    alike on both."""
    from voxgi.voxgi_addon.gi.light_injection import voxel_centres
    from voxgi.voxgi_addon.gi.update import GISettings, update_gi
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    def halves(textured):
        snap = panel_snapshot(textured)
        state = update_gi(snap, build_scene_caches(snap, 0.125, 1), GISettings(resolution=64),
                          anchor=np.zeros(3))
        glow = np.asarray(state.radiance.emission[0], np.float64)
        centres = voxel_centres(state.cascades[0])
        lit = glow.max(axis=1) > 0
        left, right = lit & (centres[:, 0] < -0.2), lit & (centres[:, 0] > 0.2)
        assert left.sum() > 10 and right.sum() > 10
        return glow[left].mean(axis=0), glow[right].mean(axis=0)

    left, right = halves(True)
    assert left[0] > 5 * left[2] and right[2] > 5 * right[0]
    left, right = halves(False)  # the same colour (the halves' coverage of their voxels differs)
    np.testing.assert_allclose(left / left.sum(), right / right.sum(), rtol=1e-3)


def test_a_repainted_emission_texture_relights_the_voxels():
    """An emission texture repainted with the same mean (its halves swapped) is a change of
    light: the next update does not reuse the voxels' light, and they glow swapped."""
    import dataclasses

    from voxgi.voxgi_addon.gi.light_injection import voxel_centres
    from voxgi.voxgi_addon.gi.update import GISettings, update_gi
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    snap = panel_snapshot()
    caches = build_scene_caches(snap, 0.125, 1)
    settings = GISettings(resolution=64)
    first = update_gi(snap, caches, settings, anchor=np.zeros(3))
    texture = snap.textures[0]
    swapped = dataclasses.replace(texture, pixels=np.ascontiguousarray(texture.pixels[:, ::-1]),
                                  key="two colours, swapped")
    again = update_gi(dataclasses.replace(snap, textures=(swapped,)), caches, settings,
                      anchor=np.zeros(3), previous=first)
    assert again.reused != "all"
    centres = voxel_centres(again.cascades[0])
    glow = np.asarray(again.radiance.emission[0], np.float64)
    left = (glow.max(axis=1) > 0) & (centres[:, 0] < -0.2)
    assert glow[left, 2].mean() > 5 * glow[left, 0].mean()  # the left half is blue now
    same = update_gi(snap, caches, settings, anchor=np.zeros(3), previous=first)
    assert same.reused == "all"


def test_bounce_hits_and_probe_rays_see_the_emission_per_texel():
    """A ray landing on the panel sees the texel it lands on (exact_indirect.hit_emission), in
    the gathers' bounce hits and the probe bakes' rays (probes.bake.hit_radiance), not the
    texture's mean: upward rays under the left half see red, under the right half blue."""
    from voxgi.voxgi_addon.gi.exact_indirect import hit_emission
    from voxgi.voxgi_addon.probes.bake import hit_radiance
    from voxgi.voxgi_addon.scene.raycast import closest_hits

    snapshot = panel_snapshot()
    tris = world_triangles(snapshot)
    origins = np.array([[-0.5, 0.0, 0.5], [0.5, 0.0, 0.5]])
    up = np.tile([0.0, 0.0, 1.0], (2, 1))
    t, tri, u, v = closest_hits(tris, origins, up)
    assert (tri >= 0).all()
    glow = hit_emission(tris, material_table(snapshot)[3], tri, u, v)
    np.testing.assert_allclose(glow, [RED * STRENGTH, BLUE * STRENGTH], rtol=1e-3)
    probe = hit_radiance(snapshot, tris, origins, up, t, tri, u, v, light_samples=1)
    np.testing.assert_allclose(probe, [RED * STRENGTH, BLUE * STRENGTH], rtol=1e-3)
    flat = panel_snapshot(textured=False)  # without the texture: the mean, both sides
    mean = hit_emission(world_triangles(flat), material_table(flat)[3], tri, u, v)
    np.testing.assert_allclose(mean[0], mean[1])


def test_probe_rays_see_the_base_color_per_texel():
    """probes.bake.hit_radiance reflects the light by the Base Color texel the ray lands on
    (as the gathers' bounce hits), not the material's mean colour."""
    import dataclasses

    from voxgi.voxgi_addon.probes.bake import hit_radiance
    from voxgi.voxgi_addon.scene.raycast import closest_hits

    flat = panel_snapshot(textured=False)  # a uniform panel: the floor's light is symmetric
    grey = dataclasses.replace(flat.materials[1], base_color_texture=0,
                               base_color=two_colour_pixels().reshape(-1, 3).mean(axis=0))
    snapshot = dataclasses.replace(flat, materials=[flat.materials[0], grey])
    tris = world_triangles(snapshot)
    origins = np.array([[-1.5, 0.0, 0.5], [1.5, 0.0, 0.5]])
    down = np.tile([0.0, 0.0, -1.0], (2, 1))
    t, tri, u, v = closest_hits(tris, origins, down)
    probe = hit_radiance(snapshot, tris, origins, down, t, tri, u, v, light_samples=16)
    ratio = probe / np.maximum(probe.sum(axis=1, keepdims=True), 1e-12)
    light = (RED + BLUE) / 2  # the panel's mean colour, on both sides
    expected = np.array([RED, BLUE]) * light
    expected /= expected.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(ratio, expected, atol=0.02)

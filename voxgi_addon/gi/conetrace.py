"""Cone tracing through a prefiltered voxel volume (Crassin 2011, as used by Yalçıner 2016 4.6).

A cone from a surface point marches front to back; each sample reads the octree at the level
whose node size matches the cone diameter there (trilinear within a level, blended between
levels), and composites premultiplied radiance and occlusion:
``c += (1 − α)·c_s·f(d)``, ``α += (1 − α)·α_s·f(d)`` with the falloff ``f(d) = 1 / (1 + λ·d)``.

The volume is anything with the ``ConeVolume`` methods (``svo.VoxelOctree`` in the product).
Volumes that also have ``sample_directional`` (the octree) are sampled anisotropically by
default (``ConeSettings.anisotropic``): each sample reads the node faces that face the cone,
so a thin wall stays opaque at coarse levels and a node straddling it shows only its near side
(Crassin et al. 2011; Gomes 2015 §4.15), which stops light leaking through thin walls.
Light cones also read each sample's colour one level finer than its occlusion and attenuate
what lies behind a sample a little more than its coverage (``ConeSettings.radiance_detail``,
``transmittance_exponent``): a 2 cm wall in 7 cm voxels passes 1.3% of the lit side's light.
Outputs are in Cycles' pass units: diffuse indirect = indirect irradiance / π (light without
albedo), AO = the cosine-weighted unoccluded fraction within the AO distance.

The world and emission (docs/gi_pipeline.md "Fast quality: world and emission"): voxels hold
their emission in their radiance (``light_injection``) and the octree keeps it apart as well
(``VoxelOctree.emission``). Glossy cones see it, and where they leave the voxels they see the
world (``WorldMips``: the remaining transmittance × the map prefiltered at the cone's aperture).
Diffuse cones give Diffuse Indirect, the light of one bounce: they subtract the emission and
add no world, both of which a surface sees as direct light (Fast's Diffuse Direct has them);
``trace_world_visibility`` gives what the same cones see of the world, for shadows by cones.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..scene.equirect import box_downsample, sample_bilinear
from ..scene.short_axis import norm3

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
WORLD_MIP_HEIGHT = 64   # rows of the finest prefiltered world map (columns: twice that)
WORLD_MIP_LAST = 2      # rows of the coarsest


@dataclass(frozen=True, eq=False)
class WorldMips:
    """The world map box-filtered into a chain of equirect maps, what a cone that leaves the
    voxels sees: ``maps[k]`` is (H_k, 2·H_k, 3) float32, H_0 ≤ WORLD_MIP_HEIGHT (the map's own
    rows when fewer), each the 2 × 2 box average of the one before, down to WORLD_MIP_LAST rows.
    ``radiance`` reads the map whose pixels are as wide as the cone (rows π / H_k ≈ the
    cone's diameter), bilinearly, blending the two nearest maps (``cone_common.glsl``
    world_radiance does the same in float32)."""

    maps: tuple

    def radiance(self, dirs, half_angle) -> np.ndarray:
        """(N, 3) float64 radiance seen along unit ``dirs`` (N, 3) by cones of ``half_angle``
        (radians, scalar or (N,))."""
        dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
        level = world_mip_level(len(self.maps[0]), len(self.maps), half_angle)
        level = np.broadcast_to(level, (len(dirs),))
        low = np.floor(level).astype(np.int64)
        t = (level - low)[:, None]
        out = np.zeros((len(dirs), 3))
        for k in np.unique(low):
            rows = np.flatnonzero(low == k)
            value = sample_bilinear(self.maps[k], dirs[rows]).astype(np.float64)
            if k + 1 < len(self.maps):
                upper = sample_bilinear(self.maps[k + 1], dirs[rows]).astype(np.float64)
                value = value * (1.0 - t[rows]) + upper * t[rows]
            out[rows] = value
        return out


def world_mip_level(base_rows: int, count: int, half_angle) -> np.ndarray:
    """Continuous map index in [0, count − 1] for cones of ``half_angle`` (radians): the map
    whose rows (π / H) are as wide as the cone's diameter, log2(base_rows · 2·half / π)."""
    width = 2.0 * np.maximum(np.asarray(half_angle, np.float64), 1e-6)
    return np.clip(np.log2(base_rows * width / math.pi), 0.0, count - 1.0)


def world_mips(radiance) -> WorldMips | None:
    """The ``WorldMips`` of an (H, W, 3) world map (``WorldData.radiance``; None or black:
    None). Values are float32 and non-negative, as the GPU table holds them."""
    if radiance is None:
        return None
    image = np.maximum(np.nan_to_num(np.asarray(radiance, np.float32), nan=0.0, posinf=0.0,
                                     neginf=0.0), 0.0)
    if not image.max() > 0:
        return None
    maps = [box_downsample(image, WORLD_MIP_HEIGHT)]
    while len(maps[-1]) > WORLD_MIP_LAST:
        maps.append(box_downsample(maps[-1], max(len(maps[-1]) // 2, WORLD_MIP_LAST)))
    return WorldMips(tuple(np.ascontiguousarray(m, np.float32) for m in maps))


class ConeVolume(Protocol):
    depth: int

    def node_size(self, level: int) -> float: ...

    def finest_level_at(self, points: np.ndarray) -> np.ndarray: ...

    def sample(self, points: np.ndarray, level: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    # Optional: sample_directional(points, level, dirs) -> (premultiplied radiance, occlusion),
    # used when present and ``anisotropic`` is on.


@dataclass(frozen=True)
class ConeSettings:
    """The thesis' cone bar, with physically neutral defaults (intensity 1, no falloff on GI).

    Defaults were chosen against Cycles on the tests' Cornell box: 16 cosine-distributed cones
    of 20° (not the thesis' 6 × 30°, which blur a 2 m room's walls together and measured
    Diffuse Indirect relative L1 0.38 vs 0.20).

    cone_angle : half-angle of the diffuse and AO cones, degrees.
    sample_factor : step between samples as a multiple of the cone diameter there.
    falloff : λ of 1/(1+λ·d) applied to occlusion (AO) and light (GI); d in metres.
    max_distance : how far diffuse/glossy cones travel, metres.
    ao_distance : AO radius in metres (Cycles' World › Ambient Occlusion distance).
    start_offset : how far from the surface a cone starts, in sizes of the finest voxels there.
    opacity_scale : multiplies sampled occlusion (clamped to 1). Surface voxels make a plane
        crossing a node fill half its children, so the octree's isotropic "present children / 8"
        reads 0.5 for a wall at every level; a scale of 2 makes such a wall opaque, as it is to
        the rays crossing it (otherwise cones leak through walls and lose half their light).
        Anisotropic sampling already reads such a wall as opaque along its normal, so 1 is the
        neutral value there.
    anisotropic : sample the volume's directional faces (``sample_directional``) when it has
        them; False, or a volume without them, uses the isotropic ``sample``.
    radiance_detail : light cones (diffuse, glossy) read the colour of each sample this many
        levels finer than its occlusion (clamped to the finest level there); 0 = the same level.
        A node-centred trilinear sample reaches a whole node beyond its point, so a coarse
        sample next to a thin wall mixes in the other side's nodes; the finer level's reach
        is half as wide, while the occlusion stays at the cone's own level, where it does not
        alias. See ``march_cones``.
    transmittance_exponent : light cones attenuate what lies behind each sample by
        (1 − α_s)^k instead of (1 − α_s) (the sample's own colour is unchanged). A surface
        between two samples is split between their trilinear weights w and 1 − w, so it passes
        w·(1 − w) ≤ 1/4 of the light behind it even when opaque; k = 1.5 makes that ≤ 1/8
        (thin-wall leak, see tests/blender/test_thin_wall_leak.py). AO keeps k = 1.
    """

    cone_angle: float = 20.0
    diffuse_cones: int = 16
    sample_factor: float = 1.0
    falloff: float = 0.0
    ao_falloff: float = 0.0
    max_distance: float = 100.0
    ao_distance: float = 1.0
    start_offset: float = 1.5
    opacity_scale: float = 1.0
    gi_intensity: float = 1.0
    ao_intensity: float = 1.0
    anisotropic: bool = True
    radiance_detail: float = 1.0
    transmittance_exponent: float = 1.5

    def __post_init__(self):
        if not 1.0 <= self.cone_angle <= 80.0:
            raise ValueError(f"cone angle must be within 1..80 degrees, got {self.cone_angle}")
        if self.diffuse_cones < 1:
            raise ValueError("at least one diffuse cone is needed")
        if self.sample_factor <= 0 or self.max_distance <= 0 or self.ao_distance <= 0:
            raise ValueError("sample factor and distances must be positive")
        if self.radiance_detail < 0 or self.transmittance_exponent < 1:
            raise ValueError("radiance detail must be ≥ 0 and the transmittance exponent ≥ 1")


def _tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to each (N, 3) unit normal (branch-free, Duff et al. 2017)."""
    n = normals
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, s


def diffuse_cone_set(count: int, half_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Cone axes in the local frame (z = normal) and their weights (sum 1).

    Six or fewer cones: one along the normal and a ring at twice the half-angle (capped at
    75°), so neighbouring cones touch (Crassin's set), weighted by cosine. More cones: a
    cosine-distributed spiral (polar θ = asin √u, golden-angle azimuths) with equal weights,
    each cone standing for an equal share of the cosine-weighted hemisphere.
    Returns dirs (K, 3), weights (K,); uniform radiance L integrates to L.
    """
    if count <= 6:
        dirs = [np.array([0.0, 0.0, 1.0])]
        polar = min(2.0 * half_angle, math.radians(75.0))
        for k in range(count - 1):
            phi = 2 * math.pi * k / (count - 1)
            dirs.append(np.array([math.sin(polar) * math.cos(phi),
                                  math.sin(polar) * math.sin(phi), math.cos(polar)]))
        dirs = np.array(dirs)
        return dirs, dirs[:, 2] / dirs[:, 2].sum()
    u = (np.arange(count) + 0.5) / count
    sin_theta = np.sqrt(u)
    phi = np.arange(count) * math.pi * (3.0 - math.sqrt(5.0))
    dirs = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi),
                     np.sqrt(1.0 - u)], axis=1)
    return dirs, np.full(count, 1.0 / count)


def march_cones(volume: ConeVolume, origins, dirs, half_angle, max_distance, *, falloff=0.0,
                sample_factor=1.0, start_offset=2.0, opacity_scale=1.0, want_light=True,
                surface_normals=None, start_height=None, anisotropic=True, radiance_detail=0.0,
                transmittance_exponent=1.0, subtract=None):
    """March N cones front to back.

    origins, dirs : (N, 3) world points (already off the surface) and unit axes.
    half_angle : radians (scalar or (N,)); max_distance : metres (scalar or (N,)).
    surface_normals, start_height : when given, a sample never reads nodes wider than 2/3 of
        its height above the surface it started from (height = start_height + d·(dir·n)), so
        grazing cones do not read the surface's own voxels (self-occlusion, self-colour).
    anisotropic : use ``volume.sample_directional`` (if the volume has it) with the cone axis.
    radiance_detail, transmittance_exponent : light cones only (``want_light``), see
        ``ConeSettings``. With radiance_detail d > 0 a sample of occlusion α_s (level ℓ) and
        premultiplied colour c_s also reads level ℓ + d (α_f, c_f) and takes the colour
        c = m·(α_s/α_f)·c_f + (1 − m)·c_s, m = min(α_f/α_s, 1): the finer colour where the
        finer level holds the occluders the coarse one sees, the coarse colour where it falls
        between them (empty fine nodes have no colour to give).
    subtract : a volume of the same nodes and occlusion (``VoxelOctree.emission``) whose
        premultiplied colour is taken off each light sample, at the same point and level,
        before the finer level's colour is mixed in (the colour is linear in it), floored at 0.
    Returns radiance (N, 3) float64 (premultiplied, composited) and occlusion α (N,) in [0, 1].
    """
    n = len(origins)
    leaf = volume.node_size(volume.depth)
    local = local_voxel_size(volume, origins)  # cones start no thinner than the voxels there
    tan_half = np.broadcast_to(np.tan(half_angle), (n,)).astype(np.float64)
    max_d = np.broadcast_to(np.asarray(max_distance, np.float64), (n,))
    radiance = np.zeros((n, 3))
    alpha = np.zeros(n)
    d = start_offset * local
    if surface_normals is not None:
        rise = (dirs * surface_normals).sum(axis=1)
        base = np.broadcast_to(np.asarray(start_height, np.float64), (n,))
    active = np.flatnonzero(d < max_d)
    directional = anisotropic and hasattr(volume, "sample_directional")
    while len(active):
        da = d[active]
        diameter = 2.0 * tan_half[active] * da
        if surface_normals is not None:
            widest = (2.0 / 3.0) * np.maximum(base[active] + da * rise[active], 1e-9)
            diameter = np.minimum(diameter, widest)
        diameter = np.maximum(diameter, local[active])
        p = origins[active] + dirs[active] * da[:, None]
        level = volume.depth - np.log2(diameter / leaf)
        if surface_normals is not None:
            # Both levels blended must respect the bound, so round the coarsest allowed up.
            level = np.maximum(level, np.ceil(volume.depth - np.log2(widest / leaf) - 1e-9))
        finest = volume.finest_level_at(p).astype(np.float64)
        level = np.clip(level, 0.0, finest)
        def colour(source, points, levels, axes, extinction=True):
            if directional:
                return source.sample_directional(points, levels, axes, extinction=extinction)
            return source.sample(points, levels)

        # Light cones see thin walls as opaque from any angle; AO keeps the plain blend
        # (measured closer to Cycles' AO on the Cornell box: 0.13 vs 0.19 relative L1).
        c_s, a_s = colour(volume, p, level, dirs[active], want_light)
        if want_light and subtract is not None:  # (empty samples have no emission to lose)
            full = np.flatnonzero(a_s > 1e-6)
            c_s[full] = np.maximum(c_s[full] - colour(subtract, p[full], level[full],
                                                      dirs[active][full])[0], 0.0)
        if want_light and radiance_detail > 0:
            fine = np.minimum(level + radiance_detail, finest)
            need = np.flatnonzero((a_s > 1e-6) & (fine > level))  # empty samples have no colour
            if len(need):
                c_f, a_f = colour(volume, p[need], fine[need], dirs[active][need])
                full = np.flatnonzero(a_f > 1e-6)
                if subtract is not None and len(full):
                    c_f[full] = np.maximum(c_f[full] - colour(
                        subtract, p[need][full], fine[need][full], dirs[active][need][full])[0],
                        0.0)
                a_c = a_s[need]
                m = np.minimum(a_f / a_c, 1.0)
                c_s[need] = ((m * a_c / np.maximum(a_f, 1e-12))[:, None] * c_f
                             + (1.0 - m)[:, None] * c_s[need])
        if opacity_scale != 1.0:  # scale α and the premultiplied radiance alike
            scaled = np.minimum(a_s * opacity_scale, 1.0)
            c_s = c_s * (scaled / np.maximum(a_s, 1e-12))[:, None]
            a_s = scaled
        step = diameter * sample_factor
        # Opacity correction for steps longer or shorter than the node size sampled.
        node = leaf * np.exp2(volume.depth - level)
        exponent = step / node * (transmittance_exponent if want_light else 1.0)
        a_s = 1.0 - np.power(np.clip(1.0 - a_s, 0.0, 1.0), exponent)
        weight = (1.0 - alpha[active]) / (1.0 + falloff * da)
        if want_light:
            radiance[active] += weight[:, None] * c_s
        alpha[active] += weight * a_s
        d[active] = da + step
        keep = (d[active] < max_d[active]) & (alpha[active] < 0.999)
        active = active[keep]
    return radiance, np.clip(alpha, 0.0, 1.0)


def local_voxel_size(volume: ConeVolume, points) -> np.ndarray:
    """(N,) size in metres of the finest voxels at each point (its finest cascade's span)."""
    finest = np.maximum(volume.finest_level_at(points), 0)
    return volume.node_size(volume.depth) * np.exp2(volume.depth - finest)


def offset_origins(points, normals, volume: ConeVolume, start_offset):
    """Lift surface points off their own voxels along the normal (in local voxel sizes)."""
    return points + normals * (start_offset * local_voxel_size(volume, points))[:, None]


def trace_diffuse_and_ao(volume: ConeVolume, points, normals, settings: ConeSettings):
    """Diffuse indirect light (N, 3) and AO (N,) from the same cone set around each normal.

    AO reuses the cones' occlusion within ``ao_distance``; diffuse uses ``max_distance``.
    Diffuse is the light of one bounce: the volume's emission (``VoxelOctree.emission``) is
    subtracted and the world is not added (a surface sees both directly: Diffuse Direct).
    """
    n = len(points)
    half = math.radians(settings.cone_angle)
    local, weights = diffuse_cone_set(settings.diffuse_cones, half)
    t, s = _tangent_frame(normals)
    origins = offset_origins(points, normals, volume, settings.start_offset)
    height = settings.start_offset * local_voxel_size(volume, points)
    diffuse = np.zeros((n, 3))
    visible = np.zeros(n)
    for (lx, ly, lz), w in zip(local, weights):
        axis = t * lx + s * ly + normals * lz
        light, _ = march_cones(volume, origins, axis, half, settings.max_distance,
                               falloff=settings.falloff, sample_factor=settings.sample_factor,
                               start_offset=0.0, opacity_scale=settings.opacity_scale,
                               surface_normals=normals, start_height=height,
                               anisotropic=settings.anisotropic,
                               radiance_detail=settings.radiance_detail,
                               transmittance_exponent=settings.transmittance_exponent,
                               subtract=getattr(volume, "emission", None))
        _, occ = march_cones(volume, origins, axis, half, settings.ao_distance,
                             falloff=settings.ao_falloff, sample_factor=settings.sample_factor,
                             start_offset=0.0, opacity_scale=settings.opacity_scale,
                             want_light=False, surface_normals=normals, start_height=height,
                             anisotropic=settings.anisotropic)
        diffuse += w * light
        visible += w * (1.0 - occ)
    ao = 1.0 - np.clip(settings.ao_intensity * (1.0 - visible), 0.0, 1.0)
    return (settings.gi_intensity * diffuse).astype(np.float32), ao.astype(np.float32)


def glossy_half_angle(roughness: np.ndarray) -> np.ndarray:
    """Cone half-angle (radians) for a GGX-like lobe of the given roughness (0 = mirror)."""
    r = np.clip(np.asarray(roughness, np.float64), 0.0, 1.0)
    return np.clip(np.arctan(r * r * 1.5), math.radians(1.0), math.radians(60.0))


def trace_world_visibility(volume: ConeVolume, points, normals, settings: ConeSettings,
                           world: WorldMips) -> np.ndarray:
    """(N, 4) float32 what the diffuse cone set sees of the world: rgb = Σ_k w_k T_k L_k and
    a = Σ_k w_k lum(L_k), with T_k the transmittance left at the end of cone k's light march
    (as ``trace_diffuse_and_ao`` marches it) and L_k the world prefiltered at the cone's
    aperture in its direction (``WorldMips``). lum(rgb) / a is the world's cosine-weighted
    visible share (``cone_shadows``: the world's Diffuse Direct with shadows by cones); under a
    uniform world of radiance L with nothing in the way rgb = L."""
    half = math.radians(settings.cone_angle)
    local, weights = diffuse_cone_set(settings.diffuse_cones, half)
    t, s = _tangent_frame(normals)
    origins = offset_origins(points, normals, volume, settings.start_offset)
    height = settings.start_offset * local_voxel_size(volume, points)
    out = np.zeros((len(points), 4))
    for (lx, ly, lz), w in zip(local, weights):
        axis = t * lx + s * ly + normals * lz
        _, alpha = march_cones(volume, origins, axis, half, settings.max_distance,
                               falloff=settings.falloff, sample_factor=settings.sample_factor,
                               start_offset=0.0, opacity_scale=settings.opacity_scale,
                               surface_normals=normals, start_height=height,
                               anisotropic=settings.anisotropic,
                               radiance_detail=0.0,
                               transmittance_exponent=settings.transmittance_exponent)
        sky = world.radiance(axis, half)
        out[:, :3] += w * (1.0 - alpha)[:, None] * sky
        out[:, 3] += w * (sky @ LUMINANCE)
    return out.astype(np.float32)


def trace_glossy(volume: ConeVolume, points, normals, view_dirs, roughness, settings: ConeSettings,
                 world: WorldMips | None = None):
    """One cone along the mirror direction of ``view_dirs`` (unit, camera → point): (N, 3).
    The cone sees the voxels' emission, and with ``world`` the world where it leaves the voxels
    (its remaining transmittance × the map prefiltered at its aperture)."""
    reflect = view_dirs - 2.0 * (view_dirs * normals).sum(axis=1, keepdims=True) * normals
    origins = offset_origins(points, normals, volume, settings.start_offset)
    half = glossy_half_angle(roughness)
    light, alpha = march_cones(volume, origins, reflect, half,
                           settings.max_distance, falloff=settings.falloff,
                           sample_factor=settings.sample_factor, start_offset=0.0,
                           opacity_scale=settings.opacity_scale,
                           anisotropic=settings.anisotropic,
                           radiance_detail=settings.radiance_detail,
                           transmittance_exponent=settings.transmittance_exponent)
    if world is not None:
        light = light + (1.0 - alpha)[:, None] * world.radiance(reflect, half)
    return (settings.gi_intensity * light).astype(np.float32)


def trace_shadow(volume: ConeVolume, points, normals, light_positions, light_radius,
                 settings: ConeSettings):
    """Soft-shadow visibility (N,) in [0, 1]: one cone to each point's light position.

    The cone's half-angle covers the light's radius as seen from the point, and it stops
    short of the light by the larger of that radius and 2 voxels there, so the surface a light
    is mounted on (an area light under a ceiling) does not shadow it. Like the diffuse cones,
    a sample never reads nodes wider than 2/3 of its height above the surface it leaves, so a
    wide cone to a near light (an emissive panel overhead) does not read that surface's own
    voxels as a shadow.
    """
    origins = offset_origins(points, normals, volume, settings.start_offset)
    height = settings.start_offset * local_voxel_size(volume, points)
    to_light = light_positions - origins
    dist = norm3(to_light)
    axis = to_light / np.maximum(dist, 1e-12)[:, None]
    radius = np.maximum(light_radius, 1e-3)
    half = np.arctan(radius / np.maximum(dist, 1e-6))
    short = np.maximum(radius, 2.0 * local_voxel_size(volume, light_positions))
    _, occ = march_cones(volume, origins, axis, half, np.maximum(dist - short, 0.0),
                         sample_factor=settings.sample_factor,
                         start_offset=0.0, opacity_scale=settings.opacity_scale, want_light=False,
                         surface_normals=normals, start_height=height,
                         anisotropic=settings.anisotropic)
    return (1.0 - occ).astype(np.float32)

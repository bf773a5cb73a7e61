"""Scene settings of VoxGI: ``Scene.voxgi`` (a ``VoxGISceneSettings``)."""
# No `from __future__ import annotations` here: bpy property annotations must stay objects.
import bpy

GRID_RESOLUTIONS = (32, 64, 128, 256, 512)


class VoxGISceneSettings(bpy.types.PropertyGroup):
    """Per-scene voxelization and cascade settings."""

    span_mode: bpy.props.EnumProperty(
        name="Voxel Fit",
        description="How the voxel span and the cascades' centre are chosen",
        items=(("AUTO", "Auto", "Fit the cascades to what the camera sees: the finest voxel span "
                "(a power of two of a metre) and grid resolution the memory budget allows for "
                "the visible geometry, centred on it rather than on the camera"),
               ("MANUAL", "Manual", "Base Span, Grid Resolution and View Ahead as set: cascades "
                "centred ahead of the camera (as in the thesis)")),
        default="AUTO",
    )
    memory_budget: bpy.props.IntProperty(
        name="Voxel Memory Budget (MB)",
        description="Auto: megabytes (10^6 bytes) the cascades' voxel volume may take (GPU atlas "
                    "plus octree, estimated); the largest grid resolution within it is used, and "
                    "the voxel caches must fit it too. 256 MB gives 64³ grids",
        default=256, min=8, soft_max=4096,
    )
    base_span: bpy.props.FloatProperty(
        name="Base Span",
        description="Manual: edge length of a voxel in the finest cascade, in metres; "
                    "each coarser cascade doubles it",
        subtype="DISTANCE",
        unit="LENGTH",
        default=0.1,
        min=0.001,
        soft_max=1.0,
        precision=3,
    )
    cascade_count: bpy.props.IntProperty(
        name="Cascades",
        description="Number of nested grids (cascades); cascade i has voxels of 2^i times "
                    "the base span",
        subtype="NONE",
        default=3,
        min=1,
        max=6,
    )
    grid_resolution: bpy.props.EnumProperty(
        name="Grid Resolution",
        description="Manual: voxels along each axis of every cascade grid (a power of two); "
                    "memory grows with its cube (Auto picks it from the memory budget)",
        items=[(str(n), f"{n}\u00b3", f"{n} voxels per axis in each cascade") for n in GRID_RESOLUTIONS],
        default="64",
    )

    view_ahead: bpy.props.FloatProperty(
        name="View Ahead",
        description="Manual: centre the cascades this far in front of the camera, as a fraction of the "
                    "finest cascade's half size (0 = on the camera as in the thesis; 1 = the "
                    "finest cascade starts at the camera and covers twice the depth of view)",
        default=1.0, min=0.0, max=1.0,
    )
    dense_depth: bpy.props.IntProperty(
        name="Dense Levels",
        description="Octree levels stored as dense 3D arrays (mips); deeper levels are sparse",
        default=6, min=1, max=9,
    )
    cone_angle: bpy.props.FloatProperty(
        name="Cone Angle",
        description="Half-angle of the diffuse and ambient-occlusion cones, in degrees",
        default=20.0, min=1.0, max=80.0,
    )
    diffuse_cones: bpy.props.IntProperty(
        name="Diffuse Cones",
        description="Cones traced around the normal for diffuse light and AO (cosine weighted)",
        default=16, min=1, max=64,
    )
    sample_factor: bpy.props.FloatProperty(
        name="Sample Factor",
        description="Distance between cone samples as a multiple of the cone diameter there",
        default=1.0, min=0.25, max=4.0,
    )
    falloff: bpy.props.FloatProperty(
        name="Falloff",
        description="λ of the 1/(1+λ·distance) falloff applied to traced light, per metre",
        default=0.0, min=0.0, soft_max=2.0,
    )
    max_distance: bpy.props.FloatProperty(
        name="Max Distance",
        description="How far diffuse and glossy cones travel, in metres",
        subtype="DISTANCE", unit="LENGTH", default=100.0, min=0.01,
    )
    ao_distance: bpy.props.FloatProperty(
        name="AO Distance",
        description="Ambient occlusion radius in metres (like World › Ambient Occlusion distance)",
        subtype="DISTANCE", unit="LENGTH", default=1.0, min=0.01,
    )
    gi_intensity: bpy.props.FloatProperty(
        name="GI Intensity",
        description="Multiplier of the traced indirect light (1 = physically based, as Cycles)",
        default=1.0, min=0.0, soft_max=8.0,
    )
    ao_intensity: bpy.props.FloatProperty(
        name="AO Intensity",
        description="Multiplier of ambient occlusion darkening (1 = as Cycles' AO pass)",
        default=1.0, min=0.0, soft_max=4.0,
    )
    light_samples: bpy.props.IntProperty(
        name="Light Samples",
        description="Shadow rays per pixel for lights with a size (area, soft point, sun angle)",
        default=16, min=1, max=256,
    )
    shadows: bpy.props.EnumProperty(
        name="Shadows",
        description="How the preview's direct light is shadowed",
        items=(("RAYS", "Rays (exact)", "Shadow rays against the scene's triangles: exact, "
                "slower (CPU)"),
               ("CONES", "Cones (soft)", "One cone per light through the voxels: soft, fast "
                "(traced on the GPU with the GPU tracer)")),
        default="RAYS",
    )
    gi_resolution: bpy.props.EnumProperty(
        name="GI Resolution",
        description="Trace indirect light and AO at every pixel or at one pixel per block, "
                    "upsampled along surfaces (faster, slightly softer)",
        items=(("AUTO", "Auto", "One pixel per block so that about 160×120 to 240×180 points are "
                "traced, whatever the image size (Full up to 240×180, Half up to 480×360, "
                "Third up to 720×540, then Quarter)"),
               ("1", "Full", "Every pixel"), ("2", "Half", "One pixel per 2×2 block (4× fewer rays)"),
               ("3", "Third", "One pixel per 3×3 block (9× fewer rays)"),
               ("4", "Quarter", "One pixel per 4×4 block (16× fewer rays)")),
        default="AUTO",
    )
    quality: bpy.props.EnumProperty(
        name="Quality",
        description="How the preview's light is computed",
        items=(("ACCURATE", "Accurate", "Exact rays through the scene's triangles for every "
                "pass (direct light, diffuse indirect, AO, glossy), gathered per GI block and "
                "denoised along surfaces; needs no voxels: close to Cycles"),
               ("FAST", "Fast", "Cone tracing through the voxel octree (the thesis' method): "
                "approximate")),
        default="ACCURATE",
    )
    glossy_indirect: bpy.props.BoolProperty(
        name="Glossy Indirect",
        description="Trace glossy reflections of the scene (exact rays in Accurate quality, "
                    "cones through the voxels in Fast); off leaves the Glossy Indirect pass "
                    "black",
        default=True,
    )
    gi_rays: bpy.props.IntProperty(
        name="GI Rays",
        description="Exact rays per gather point for diffuse indirect light and AO (Accurate "
                    "quality), and an eighth of them for glossy reflections; more rays, less "
                    "noise before denoising",
        default=64, min=1, max=1024,
    )
    sparse_gathers: bpy.props.BoolProperty(
        name="Sparse Gathers",
        description="F12 and Render Preview trace the diffuse indirect light at one gather "
                    "point in four where surfaces are smooth, at every point where they meet "
                    "and at the 5% of the others whose fill would be furthest off, each with "
                    "1.5 times the GI Rays; the filter fills the rest (about half the rays; on "
                    "the test scenes within 0-5% of every point's error against Cycles). With "
                    "a gather point per pixel the glossy light is gathered the same way, but "
                    "at every point of a full metal. Off: every gather point, GI Rays each",
        default=True,
    )
    bounce_source: bpy.props.EnumProperty(
        name="Bounces",
        description="How many bounces of diffuse light the preview carries",
        items=(("CYCLES", "Follow Cycles", "As many as Cycles' Light Paths allow (Diffuse "
                "bounces, capped by Total): the preview predicts the final render"),
               ("MANUAL", "Manual", "The Bounces count below")),
        default="CYCLES",
    )
    bounces: bpy.props.IntProperty(
        name="Bounces",
        description="Diffuse bounces of the preview: 1 is the one-bounce gather (or cones); "
                    "more add the later bounces from a radiance cache in voxels",
        default=4, min=1, max=16,
    )
    seed: bpy.props.IntProperty(
        name="Seed",
        description="Seed of the sampling patterns (shadow rays and gathers), as Cycles' Seed: "
                    "the same seed gives the same noise, so still parts of an animation do not "
                    "flicker",
        default=0, min=0, max=2 ** 20,
    )
    use_animated_seed: bpy.props.BoolProperty(
        name="Animated Seed",
        description="Use a different seed on every frame (Cycles' Use Animated Seed): the noise "
                    "changes from frame to frame",
        default=False,
    )
    tracer: bpy.props.EnumProperty(
        name="Tracer",
        description="Where the preview's cone tracing runs",
        items=(("AUTO", "GPU if available", "GPU compute shaders when a GPU context can be had, "
                "else the numpy tracer (reported)"),
               ("NUMPY", "numpy (CPU)", "The numpy reference tracer: slower, always available")),
        default="AUTO",
    )

    # Light probes (docs/probes.md): placement, bake, masks, validity, display.
    indirect_source: bpy.props.EnumProperty(
        name="Indirect Light",
        description="Where the preview's and F12's Diffuse Indirect comes from",
        items=(("CONES", "Cone Tracing", "Cones traced through the voxel octree every update"),
               ("PROBES", "Light Probes", "The baked light probes (Bake Probes), interpolated "
                "through their occlusion masks")),
        default="CONES",
    )
    probe_resolution: bpy.props.IntProperty(
        name="Probe Volumes",
        description="k: the probe box is split into k × k × k volumes; volumes holding geometry "
                    "get probes at their corners (at most (k+1)³)",
        default=8, min=1, max=64,
    )
    probe_placement: bpy.props.EnumProperty(
        name="Probe Boxes",
        description="Which boxes get probe grids",
        items=(("AUTO", "Volumes or Scene", "Each Light Probe Volume object's box (its resolution "
                "sets the volumes per axis), or the scene's bounds when there is none"),
               ("SCENE", "Scene Bounds", "One grid over the bounds of all geometry, k per axis")),
        default="AUTO",
    )
    probe_directions: bpy.props.IntProperty(
        name="Probe Rays",
        description="Rays per probe for its radiance and validity (the same directions for "
                    "every probe)", default=256, min=16, max=4096,
    )
    probe_seed: bpy.props.IntProperty(
        name="Seed", description="Fixes the ray directions and light sampling of the bake",
        default=0, min=0,
    )
    probe_masks: bpy.props.BoolProperty(
        name="Occlusion Masks",
        description="Per probe, the sub-volumes it may light (Bowald's 4×4×4 masks); off lets "
                    "every probe light its whole volume", default=True,
    )
    probe_mask_threshold: bpy.props.FloatProperty(
        name="Mask Threshold",
        description="Share of a sub-volume's surface that must face the probe for its light to "
                    "pass", default=0.5, min=0.0, max=1.0, subtype="FACTOR",
    )
    probe_validity: bpy.props.FloatProperty(
        name="Validity Threshold",
        description="Probes whose rays hit back faces more often than this are inside geometry: "
                    "relocated or disabled", default=0.25, min=0.0, max=1.0, subtype="FACTOR",
    )
    probe_relocate: bpy.props.BoolProperty(
        name="Relocate Invalid", description="Move invalid probes out of geometry (else disable "
        "them)", default=True,
    )
    probe_bake_method: bpy.props.EnumProperty(
        name="Bake With",
        description="How probe radiance is found",
        items=(("RAYS", "Exact Rays (CPU)", "Rays against the triangles, direct light with shadow "
                "rays at each hit"),
               ("VOXELS_GPU", "Voxel Octree (GPU)", "Narrow cones through the voxel octree's "
                "injected light, on the GPU (numpy without one); needs Update")),
        default="RAYS",
    )
    probe_display: bpy.props.BoolProperty(
        name="Show Probes", description="Draw the baked probes and active volumes in the 3D view",
        default=True,
    )
    probe_display_size: bpy.props.FloatProperty(
        name="Probe Size", description="Radius of the drawn probe spheres", default=0.05,
        min=0.001, soft_max=1.0, subtype="DISTANCE", unit="LENGTH",
    )
    probe_selected: bpy.props.IntProperty(
        name="Inspect Probe", description="Draw the sub-volumes this probe may light (-1: none)",
        default=-1, min=-1,
    )


def probe_settings(settings: VoxGISceneSettings, resolution=None):
    """The engine's ProbeSettings from the scene settings (``resolution`` overrides k)."""
    from ..voxgi_addon.probes.bake import ProbeSettings

    return ProbeSettings(resolution=resolution or settings.probe_resolution,
                         directions=settings.probe_directions, seed=settings.probe_seed,
                         use_masks=settings.probe_masks,
                         mask_threshold=settings.probe_mask_threshold,
                         validity_threshold=settings.probe_validity,
                         relocate=settings.probe_relocate, bounces=diffuse_bounces(settings))


def cone_settings(settings: VoxGISceneSettings):
    """The engine's ConeSettings from the scene settings."""
    from ..voxgi_addon.gi.conetrace import ConeSettings

    return ConeSettings(cone_angle=settings.cone_angle, diffuse_cones=settings.diffuse_cones,
                        sample_factor=settings.sample_factor, falloff=settings.falloff,
                        max_distance=settings.max_distance, ao_distance=settings.ao_distance,
                        gi_intensity=settings.gi_intensity, ao_intensity=settings.ao_intensity)


def gi_stride(settings: VoxGISceneSettings, width: int, height: int) -> int:
    """The GI resolution stride for a ``width`` × ``height`` image (``auto_stride`` for Auto)."""
    from ..voxgi_addon.preview.upsample import auto_stride

    if settings.gi_resolution == "AUTO":
        return auto_stride(width, height)
    return int(settings.gi_resolution)


def sampling_seed(settings: VoxGISceneSettings, frame: int) -> int:
    """The sampling seed of ``frame``: the scene's Seed, plus the frame with Animated Seed."""
    return int(settings.seed) + (int(frame) if settings.use_animated_seed else 0)


def pixel_filter_width(scene) -> float:
    """The anti-aliased preview's pixel Filter Size: Cycles' (Render Properties › Film ›
    Pixel Filter, Blackman-Harris) when Cycles is there to own it, else its default 1.5 px."""
    from ..voxgi_addon.scene.camera import DEFAULT_FILTER_WIDTH

    cycles = getattr(scene, "cycles", None)
    width = getattr(cycles, "filter_width", None)
    return DEFAULT_FILTER_WIDTH if width is None else float(width)


def diffuse_bounces(settings: VoxGISceneSettings) -> int:
    """The preview's diffuse bounces: the Manual count, or Cycles' Light Paths (Diffuse bounces
    capped by Total, at least 1) when it follows Cycles."""
    if settings.bounce_source == "MANUAL":
        return int(settings.bounces)
    cycles = getattr(settings.id_data, "cycles", None)
    diffuse = getattr(cycles, "diffuse_bounces", 4)
    total = getattr(cycles, "max_bounces", 12)
    return max(1, min(int(diffuse), int(total)))


def glossy_chains(settings: VoxGISceneSettings) -> bool:
    """Whether a glossy scatter goes on past the one diffuse bounce (``GatherSettings
    .glossy_chains``): Accurate quality following Cycles' Light Paths at Diffuse 1, with
    Glossy above 0 and Total above 1 (a Total of 1 ends every path at its first bounce)."""
    cycles = getattr(settings.id_data, "cycles", None)
    if settings.quality != "ACCURATE" or settings.bounce_source == "MANUAL" or cycles is None:
        return False
    diffuse = int(getattr(cycles, "diffuse_bounces", 4))
    total = int(getattr(cycles, "max_bounces", 12))
    # (Diffuse 0, which the preview draws as 1, has no diffuse bounce for glossy ones to follow)
    return diffuse == 1 and total > 1 and int(getattr(cycles, "glossy_bounces", 4)) > 0


def trace_options(settings: VoxGISceneSettings, width: int, height: int, frame: int = 0) -> dict:
    """Keyword arguments of both tracers (``preview.passes.render_passes``,
    ``render.gpu_preview.render_passes_gpu``) for a ``width`` × ``height`` image of ``frame``."""
    from ..voxgi_addon.preview.gather import GatherSettings

    return {"light_samples": settings.light_samples, "shadows": settings.shadows,
            "filter_width": pixel_filter_width(settings.id_data),
            "gi_stride": gi_stride(settings, width, height), "quality": settings.quality,
            "glossy_indirect": settings.glossy_indirect,
            "gather_settings": GatherSettings(rays=settings.gi_rays,
                                              glossy_rays=max(1, settings.gi_rays // 8),
                                              ao_distance=settings.ao_distance,
                                              seed=sampling_seed(settings, frame),
                                              bounces=diffuse_bounces(settings),
                                              sparse=settings.sparse_gathers,
                                              glossy_chains=glossy_chains(settings))}


def gi_settings(settings: VoxGISceneSettings):
    """The engine's GISettings from the scene settings."""
    from ..voxgi_addon.gi.update import GISettings

    return GISettings(resolution=grid_resolution(settings), dense_depth=settings.dense_depth,
                      view_ahead=settings.view_ahead)


def fit_settings(settings: VoxGISceneSettings):
    """The engine's view-fit settings (Auto mode) from the scene settings."""
    from ..voxgi_addon.gi.view_fit import FitSettings

    return FitSettings(budget_bytes=int(settings.memory_budget) * 1_000_000,
                       cascade_count=settings.cascade_count, dense_depth=settings.dense_depth)


def is_auto(settings: VoxGISceneSettings) -> bool:
    """True when the cascades are fitted to the view (``span_mode`` Auto)."""
    return settings.span_mode == "AUTO"


def grid_resolution(settings: VoxGISceneSettings) -> int:
    """The per-cascade grid resolution of ``settings`` in voxels per axis."""
    return int(settings.grid_resolution)


classes = (VoxGISceneSettings,)


def register() -> None:
    bpy.types.Scene.voxgi = bpy.props.PointerProperty(
        type=VoxGISceneSettings,
        name="VoxGI",
        description="VoxGI voxel global illumination settings of this scene",
    )


def unregister() -> None:
    del bpy.types.Scene.voxgi

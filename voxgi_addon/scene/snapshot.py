"""The scene snapshot: the engine's only input.

A frozen, bpy-free description of a Blender scene, taken on the main thread by
``operators/scene_snapshot.py`` with ``foreach_get``. Everything is plain numpy or
Python scalars so the worker thread and plain pytest can use it.

Spaces and units
----------------
* Mesh positions are in **object space** (metres before the object transform).
* Matrices are 4x4, column-vector convention (``world = M @ [x, y, z, 1]``), float64,
  exactly as ``Object.matrix_world`` gives them.
* Colours are linear scene-referred RGB, float32.
* Light power follows Blender/Cycles: watts for point/spot/area lights, W/m² (strength)
  for sun lights.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

OBJECT_KINDS = ("static", "rigid", "skinned")
# Cycles' ray visibility (Object › Visibility › Ray Visibility): the bits of
# ``ObjectData.visibility``, one per kind of ray that may see the object.
RAY_CAMERA, RAY_DIFFUSE, RAY_GLOSSY, RAY_SHADOW = 1, 2, 4, 8
RAY_ALL = RAY_CAMERA | RAY_DIFFUSE | RAY_GLOSSY | RAY_SHADOW
LIGHT_TYPES = ("SUN", "POINT", "SPOT", "AREA")


@dataclass(frozen=True)
class SkinData:
    """Per-vertex skinning of a mesh (rest pose).

    weights : (V, 4) float32, each row sums to 1 (or 0 for a vertex no deform bone moves).
    bone_indices : (V, 4) uint8, indices into ``ArmatureData.bone_names``.
    armature : name of the ``ArmatureData`` the indices refer to.
    """

    weights: np.ndarray
    bone_indices: np.ndarray
    armature: str


@dataclass(frozen=True)
class MeshData:
    """A triangulated mesh in object space.

    positions : (V, 3) float32, object space.
    triangles : (T, 3) int32 vertex indices (Blender loop triangles).
    triangle_materials : (T,) int32 index into ``SceneSnapshot.materials`` (-1 = none).
    uvs : (T, 3, 2) float32 UV of each triangle corner — of the UV map its material's textures
        name, else the active render UV map — or None when the mesh has no UV map.
    skin : rest-pose skinning, or None for a mesh that no armature deforms.
    corner_normals : (T, 3, 3) float32 object-space shading normal at each triangle corner
        (Blender's ``Mesh.corner_normals``: smooth, flat or custom), or None (face normals).
    """

    name: str
    positions: np.ndarray
    triangles: np.ndarray
    triangle_materials: np.ndarray
    uvs: np.ndarray | None = None
    skin: SkinData | None = None
    corner_normals: np.ndarray | None = None


@dataclass(frozen=True)
class TextureData:
    """An image a material's socket samples per texel (docs/gi_pipeline.md "Materials per
    texel"): an Image Texture node's, or Cycles' bake of a node tree into the mesh's UV map.

    pixels : (H, W, 3) or (H, W, 4) float32, row 0 = the bottom row (v = 0), as ``Image.pixels``
        holds them: linear RGB (sRGB byte images linearised), a Non-Color image's values as
        they are, and the image's alpha where a material reads it (4 channels).
    interpolation : 'Linear' (bilinear) or 'Closest'.
    extension : 'REPEAT', 'EXTEND' (clamp to the edge) or 'CLIP' (black outside [0, 1]).
    uv_transform : (2, 3) float64 affine map of a surface's UV (u, v, 1) to the image's
        coordinates (the Mapping nodes in front of the image; the identity without).
    key : content key of the pixels (same pixels → same key; caches of mip pyramids and
        uploads).
    srgb_bytes : the image is a byte image in the sRGB colour space. Cycles keeps such an
        image's encoded bytes, interpolates them and decodes the result, so between two texels
        it reads darker than a linear blend (docs/gi_pipeline.md "Byte images blend in sRGB").
    """

    name: str
    pixels: np.ndarray
    interpolation: str = "Linear"
    extension: str = "REPEAT"
    uv_transform: np.ndarray = field(default_factory=lambda: np.eye(2, 3))
    key: str = ""
    srgb_bytes: bool = False


@dataclass(frozen=True)
class MaterialData:
    """What the engine needs of a material (Principled BSDF inputs).

    base_color : (3,) float32 linear RGB (the input's value, or the mean of its texture: what
        a per-material table uses).
    emission : (3,) float32 linear RGB, colour × strength (with an emission texture, its mean ×
        the strength: what a per-material table uses).
    base_color_texture : index into ``SceneSnapshot.textures`` of the texture giving the Base
        Color per texel through the meshes' ``uvs``, or -1 (the value is uniform).
    alpha : the Alpha socket's value (1 opaque); alpha_texture : index of the texture whose
        4th channel gives the Alpha per texel (-1: ``alpha`` everywhere).
    param_texture : index of the texture whose channels 0 and 1 give Roughness and Metallic
        per texel (-1: ``roughness``, ``metallic`` everywhere, which are then the texture's
        means); param_variants : index of the first of ``textures.PARAM_VARIANTS`` materials
        that follow it, this material at each quantized (roughness, metallic) — what a surface
        point shades with (``textures.SurfaceTextures.variant_at``).
    normal_texture : index of a tangent-space normal map's texture (its Normal Map node's Color
        input) perturbing the shading normal of what the camera sees, ``normal_strength`` its
        Strength; -1: none.
    emission_texture : index of the texture giving the Emission Color per texel through the
        meshes' ``uvs`` (its RGB × ``emission_strength`` is the emission there); -1: none
        (``emission`` everywhere).
    transmission : (3,) float32 the Principled BSDF's transmission lobe, Transmission Weight ×
        (1 − Metallic) × its Base Color (the glass' tint); zeros for opaque materials. Such a
        material's ``base_color`` is its diffuse part only (Base Color × (1 − that weight)),
        as Cycles mixes the lobes. ``ior`` : its IOR (the glass' Fresnel reflection).
        ``preview.transmission`` renders it as a thin surface.
    """

    name: str
    base_color: np.ndarray
    roughness: float = 0.5
    metallic: float = 0.0
    specular: float = 0.5
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    base_color_texture: int = -1
    alpha: float = 1.0
    alpha_texture: int = -1
    param_texture: int = -1
    param_variants: int = -1
    normal_texture: int = -1
    normal_strength: float = 1.0
    emission_texture: int = -1
    emission_strength: float = 1.0
    transmission: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    ior: float = 1.5


@dataclass(frozen=True)
class ArmatureData:
    """An armature object with its deform bones.

    bone_names : bone names, index = bone index used by ``SkinData.bone_indices``.
    parents : (B,) int32 parent bone index, -1 for a root.
    rest_matrices : (B, 4, 4) float64 bone rest matrices in armature space (``Bone.matrix_local``).
    pose_matrices : (B, 4, 4) float64 posed matrices in armature space (``PoseBone.matrix``).
    world_matrix : (4, 4) float64 the armature object's world matrix.
    """

    name: str
    bone_names: tuple[str, ...]
    parents: np.ndarray
    rest_matrices: np.ndarray
    pose_matrices: np.ndarray
    world_matrix: np.ndarray


@dataclass(frozen=True)
class ObjectData:
    """A visible mesh object instance.

    mesh : key into ``SceneSnapshot.meshes`` (linked duplicates share one key).
    world_matrix : (4, 4) float64.
    kind : 'static' (never moves), 'rigid' (animated or constrained transform) or 'skinned'.
    armature : name of the deforming ``ArmatureData`` for skinned objects, else None.
    visibility : the ``RAY_*`` bits of the rays that see it (Cycles' ray visibility).
    holdout : a holdout (``Object.holdout_get``): camera rays that meet it see nothing
        (every pass 0, as Cycles' transparent hole); other rays see its material.
    materials : (mesh's material index, this object's) pairs: where its mesh's triangles use
        the first, this object's use the second (a Base Color that varies per object, by
        Object Info › Random); empty: the mesh's own (``geometry.object_materials``).
    """

    name: str
    mesh: str
    world_matrix: np.ndarray
    kind: str = "static"
    armature: str | None = None
    visibility: int = RAY_ALL
    holdout: bool = False
    materials: tuple[tuple[int, int], ...] = ()


@dataclass(frozen=True)
class LightData:
    """A light. ``power`` is watts (point/spot/area) or W/m² strength (sun).

    world_matrix : (4, 4) float64; lights shine along their local -Z.
    color : (3,) float32 linear RGB.
    radius : soft-shadow radius in metres (point/spot); angle : sun disc angle in radians.
    spot_size, spot_blend : as in Blender (radians, 0..1).
    size, size_y : area light extent in metres; shape : 'SQUARE', 'RECTANGLE', 'DISK', 'ELLIPSE'.
    cast_shadow : Light › Cast Shadow (False: nothing occludes it, as Cycles renders it).
    """

    name: str
    type: str
    color: np.ndarray
    power: float
    world_matrix: np.ndarray
    radius: float = 0.0
    angle: float = 0.0
    spot_size: float = 0.0
    spot_blend: float = 0.0
    size: float = 0.0
    size_y: float = 0.0
    shape: str = "SQUARE"
    cast_shadow: bool = True


@dataclass(frozen=True)
class CameraData:
    """The scene camera.

    world_matrix : (4, 4) float64; the camera looks along its local -Z.
    projection_matrix : (4, 4) float64 OpenGL-style, for ``resolution``.
    resolution : (width, height) in pixels after the render percentage.
    sensor_fit : Blender's Sensor Fit ("AUTO", "HORIZONTAL", "VERTICAL"): which field of
        view an image of another aspect than ``resolution``'s keeps (``camera._frustum``).
    """

    name: str
    world_matrix: np.ndarray
    projection_matrix: np.ndarray
    resolution: tuple[int, int]
    type: str = "PERSP"
    angle_x: float = 0.0
    angle_y: float = 0.0
    ortho_scale: float = 0.0
    clip_start: float = 0.1
    clip_end: float = 100.0
    sensor_fit: str = "AUTO"


@dataclass(frozen=True)
class WorldData:
    """The world background: what a camera ray that misses everything sees in Cycles.

    radiance : (H, W, 3) float32 equirect map of linear RGB radiance in Cycles' units
        (Background Color x Strength applied), W = 2H, in the convention of
        ``voxgi_addon/scene/equirect.py`` (the only place it is defined; world space, Z up).
        None is a black world (no world, or strength 0).
    color, strength : an ambient term, ``color * strength`` (probes and voxel injection):
        a uniform world's Background Color and Strength; for a map its solid-angle-weighted
        mean radiance and 1.0.
    key : a content key of the world (same world content -> same key; "" for no world), for
        caching tables built from ``radiance``.
    """

    color: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    strength: float = 0.0
    radiance: np.ndarray | None = None
    key: str = ""


@dataclass(frozen=True)
class SceneSnapshot:
    """Everything the engine reads of a scene at one frame.

    holdout_materials : indices into ``materials`` of Holdout shaders (black to every ray; a
    camera ray that meets one sees nothing, as at a holdout object).
    film_transparent : Render › Film › Transparent (``preview.film``: alpha instead of the
    world behind the geometry).
    refractive_caustics : Cycles' Light Paths › Caustics › Refractive: light reaches diffuse
    surfaces through glass (``scene.glass.ray_alpha``); off, glass stops it, as in Cycles.
    object_colors : each object's Object Info › Color (RGBA, aligned with ``objects``) where a
    material's Base Color reads it (their variants in ``ObjectData.materials``), else empty:
    what a later snapshot that keeps those variants checks.
    """

    meshes: dict[str, MeshData]
    materials: list[MaterialData]
    objects: list[ObjectData]
    armatures: dict[str, ArmatureData] = field(default_factory=dict)
    lights: list[LightData] = field(default_factory=list)
    camera: CameraData | None = None
    world: WorldData = field(default_factory=WorldData)
    frame: int = 1
    warnings: tuple[str, ...] = ()
    textures: tuple[TextureData, ...] = ()
    holdout_materials: tuple[int, ...] = ()
    film_transparent: bool = False  # Film › Transparent: no world behind the geometry
    refractive_caustics: bool = True  # Cycles' Caustics › Refractive: light through glass
    object_colors: tuple = ()

"""GFG-like file format: constants and on-disk struct layouts (see ``docs/gfg.md``).

Everything on disk is little-endian; every struct below is a numpy structured dtype with
explicit ``<`` fields, so ``np.frombuffer(buffer, DTYPE, count, offset)`` maps it without a
copy. Matrices are row-major 4x4 for column vectors (``world = M @ [x, y, z, 1]``).
"""
from __future__ import annotations

import numpy as np

MAGIC = b"GFG "
ENDIAN_TAG = 0x0A0B0C0D  # reads back as this value only when decoded little-endian
VERSION_MAJOR = 1  # readers reject another major version
VERSION_MINOR = 2  # minor versions only add (sections, roles, trailing info fields)
# From 1.1 every padding and reserved byte must be zero and readers check it, so that with the
# checksums every byte of a file is verified (docs/gfg.md, "Every byte is checked"). Files of
# 1.0, which did not promise zero padding, are read by the 1.0 rules.
ZERO_PADDING_SINCE = (1, 1)
ALIGNMENT = 64  # sections start on 64-byte file offsets; arrays on 64-byte section offsets
NONE = 0xFFFFFFFF  # "no reference" in u32 fields (material of an unassigned range, ...)

SECTION_REQUIRED = 1  # section flag: a reader that does not know the kind must refuse the file

# ------------------------------------------------------------------ file header and table
FILE_HEADER = np.dtype([
    ("magic", "S4"),
    ("endian_tag", "<u4"),
    ("version_major", "<u2"),
    ("version_minor", "<u2"),
    ("header_size", "<u4"),
    ("file_size", "<u8"),
    ("table_offset", "<u8"),
    ("section_count", "<u4"),
    ("table_crc", "<u4"),
    ("flags", "<u4"),  # none defined: 0 (checked from 1.1)
    ("alignment", "<u4"),  # ALIGNMENT (checked from 1.1)
    ("reserved", "<u4", (3,)),  # 0 (checked from 1.1)
    ("header_crc", "<u4"),  # crc32 of bytes [0, 60)
])
assert FILE_HEADER.itemsize == 64
HEADER_CRC_SPAN = 60

SECTION_ENTRY = np.dtype([
    ("kind", "S4"),
    ("version", "<u2"),
    ("flags", "<u2"),
    ("offset", "<u8"),  # absolute, multiple of ALIGNMENT
    ("size", "<u8"),
    ("crc", "<u4"),  # crc32 of the section's bytes
    ("reserved", "<u4"),
])
assert SECTION_ENTRY.itemsize == 32

# Every section: prelude, kind-specific info struct at offset 16, array table, aligned arrays.
SECTION_PRELUDE = np.dtype([
    ("info_size", "<u4"),
    ("array_count", "<u4"),
    ("array_table_offset", "<u8"),  # multiple of 8, after the info struct
])
assert SECTION_PRELUDE.itemsize == 16

ARRAY_DESC = np.dtype([
    ("role", "<u4"),
    ("data_type", "<u4"),
    ("offset", "<u8"),  # from the section start, multiple of 8 (writers use ALIGNMENT)
    ("count", "<u8"),  # elements
    ("element_size", "<u4"),  # bytes per element (= the type's size, or a record/vertex stride)
    ("reserved", "<u4"),
])
assert ARRAY_DESC.itemsize == 32


# ------------------------------------------------------------------ section kinds
class Kind:
    STRINGS = b"STRG"
    NODES = b"NODE"
    MATERIALS = b"MATL"
    MESH = b"MESH"
    SKELETON = b"SKEL"
    ANIMATION = b"ANIM"
    VOXEL_SET = b"VXST"
    VOXEL_CACHE = b"VOXC"
    PROBE_GRID = b"PRBG"


KNOWN_KINDS = (Kind.STRINGS, Kind.NODES, Kind.MATERIALS, Kind.MESH, Kind.SKELETON,
               Kind.ANIMATION, Kind.VOXEL_SET, Kind.VOXEL_CACHE, Kind.PROBE_GRID)
SINGLETON_KINDS = (Kind.STRINGS, Kind.NODES, Kind.MATERIALS, Kind.VOXEL_SET)
SECTION_VERSION = 1  # every kind is at version 1 in formats 1.0 to 1.2


# ------------------------------------------------------------------ enums of the original GFG
class Topology:
    TRIANGLES, STRIP, LINES, POINTS = 0, 1, 2, 3


class Logic:
    """Vertex component meaning (the original's order)."""

    POSITION, UV, NORMAL, TANGENT, BINORMAL, WEIGHT, WEIGHT_INDEX, COLOR = range(8)
    NAMES = ("POSITION", "UV", "NORMAL", "TANGENT", "BINORMAL", "WEIGHT", "WEIGHT_INDEX", "COLOR")


class MaterialLogic:
    EMPTY, LAMBERT, PHONG, DX11, PRINCIPLED = range(5)  # PRINCIPLED is ours
    NAMES = ("EMPTY", "LAMBERT", "PHONG", "DX11", "PRINCIPLED")


class PrincipledSlot:
    """Uniform/texture slots of a PRINCIPLED material (Blender's Principled BSDF inputs)."""

    BASE_COLOR, ROUGHNESS, METALLIC, SPECULAR, EMISSION_COLOR, EMISSION_STRENGTH, ALPHA = range(7)


class LambertSlot:
    COLOR = 0  # = the original's Phong COLOR slot


class NodeKind:
    EMPTY, MESH, ARMATURE = 0, 1, 2
    NAMES = ("EMPTY", "MESH", "ARMATURE")


class BoneFlag:
    DEFORM, CONNECTED = 1, 2


class AnimLayout:
    KEYS_OF_BONES, BONES_OF_KEYS = 0, 1  # bone-major / key-major rotation arrays


class AnimType:
    WITH_HIP_TRANSLATE, ONLY_QUATERNION = 0, 1


class Interpolation:
    SLERP, CUBIC = 0, 1


class QuatLayout:
    WXYZ, XYZW = 0, 1


class StringType:
    ASCII, UTF8 = 1, 2


# ------------------------------------------------------------------ array roles per kind
class Role:
    # STRG
    STRING_OFFSETS, STRING_BYTES = 1, 2
    # NODE
    NODES, POSE_NODES, POSE_ROTATIONS, POSE_LOCATIONS, POSE_SCALES = 1, 2, 3, 4, 5
    # MATL
    MATERIALS, UNIFORMS, TEXTURES = 1, 2, 3
    # MESH
    VERTEX_BLOCK, COMPONENTS, INDICES, RANGES = 1, 2, 3, 4
    # SKEL
    BONES, REST_MATRICES = 1, 2
    # ANIM
    KEY_TIMES, HIP_TRANSLATIONS, ROTATIONS = 1, 2, 3
    # VXST
    CACHE_KEYS, BINDINGS, SKIPPED = 1, 2, 3
    # VOXC
    VOXEL_POSITIONS, VOXEL_NORMALS, VOXEL_COLORS, VOXEL_WEIGHTS, VOXEL_BONE_INDICES = 1, 2, 3, 4, 5
    # PRBG
    PROBE_POSITIONS, PROBE_SH, VOLUME_CELLS, VOLUME_PROBES, VOLUME_MASKS = 1, 2, 3, 4, 5
    SH_INDEX, MASK_INDEX, PROBE_VALIDITY, PROBE_FLAGS = 6, 7, 8, 9  # from format 1.2


# ------------------------------------------------------------------ info structs
STRINGS_INFO = np.dtype([("count", "<u4"), ("reserved", "<u4")])
NODES_INFO = np.dtype([("node_count", "<u4"), ("pose_count", "<u4")])
MATERIALS_INFO = np.dtype([("material_count", "<u4"), ("uniform_count", "<u4"),
                           ("texture_count", "<u4"), ("reserved", "<u4")])
MESH_INFO = np.dtype([
    ("name", "<u4"), ("topology", "<u4"), ("vertex_count", "<u8"), ("index_count", "<u8"),
    ("index_size", "<u4"), ("skeleton", "<i4"), ("aabb_min", "<f4", (3,)),
    ("aabb_max", "<f4", (3,)), ("component_count", "<u4"), ("range_count", "<u4"),
])
SKELETON_INFO = np.dtype([("name", "<u4"), ("bone_count", "<u4")])
ANIMATION_INFO = np.dtype([
    ("name", "<u4"), ("skeleton", "<u4"), ("node", "<i4"), ("key_count", "<u4"),
    ("bone_count", "<u4"), ("layout", "<u4"), ("type", "<u4"), ("interpolation", "<u2"),
    ("quat_layout", "<u2"), ("hip_bone", "<u4"), ("frame_rate", "<f4"),
])
VOXEL_SET_INFO = np.dtype([
    ("base_span", "<f8"), ("cascade_count", "<u4"), ("key_count", "<u4"),
    ("binding_count", "<u4"), ("skipped_count", "<u4"),
])
VOXEL_CACHE_INFO = np.dtype([
    ("key", "<u4"), ("cascade", "<u4"), ("span", "<f8"), ("origin_cell", "<i4", (3,)),
    ("dims", "<u4", (3,)), ("voxel_count", "<u8"), ("flags", "<u4"), ("reserved", "<u4"),
])
VOXEL_CACHE_SKINNED = 1
PROBE_GRID_INFO_1_1 = np.dtype([
    ("origin", "<f8", (3,)), ("cell_size", "<f8"), ("dims", "<u4", (3,)),
    ("probe_count", "<u4"), ("volume_count", "<u4"), ("sh_coefficients", "<u4"),
])
# Format 1.2 appends the per-axis volume size and the masks' threshold (docs/gfg.md "PRBG").
PROBE_GRID_INFO = np.dtype(PROBE_GRID_INFO_1_1.descr + [
    ("volume_size", "<f8", (3,)), ("mask_threshold", "<f4"), ("reserved", "<u4"),
])
assert PROBE_GRID_INFO_1_1.itemsize == 56 and PROBE_GRID_INFO.itemsize == 88
PROBE_FLAG_BITS = 0x3  # RELOCATED | DISABLED (voxgi_addon/probes/grid.py)
SH_L2_COEFFICIENTS = 9

# ------------------------------------------------------------------ record structs
NODE_RECORD = np.dtype([
    ("parent", "<i4"), ("kind", "<u4"), ("mesh", "<i4"), ("skeleton", "<i4"),
    ("armature_node", "<i4"), ("name", "<u4"),
    ("translation", "<f4", (3,)), ("rotation", "<f4", (3,)), ("scale", "<f4", (3,)),
    ("parent_inverse", "<f4", (4, 4)), ("world", "<f4", (4, 4)), ("reserved", "<u4"),
])
assert NODE_RECORD.itemsize == 192
MATERIAL_RECORD = np.dtype([
    ("name", "<u4"), ("logic", "<u4"), ("uniform_start", "<u4"), ("uniform_count", "<u4"),
    ("texture_start", "<u4"), ("texture_count", "<u4"),
])
UNIFORM_RECORD = np.dtype([("slot", "<u4"), ("data_type", "<u4"), ("value", "<f4", (4,))])
TEXTURE_RECORD = np.dtype([("slot", "<u4"), ("string_type", "<u4"), ("path", "<u4"),
                           ("reserved", "<u4")])
COMPONENT_RECORD = np.dtype([("logic", "<u4"), ("data_type", "<u4"), ("block", "<u4"),
                             ("offset", "<u4")])
RANGE_RECORD = np.dtype([("material", "<u4"), ("reserved", "<u4"), ("index_offset", "<u8"),
                         ("index_count", "<u8")])
BONE_RECORD = np.dtype([
    ("parent", "<i4"), ("name", "<u4"), ("flags", "<u4"), ("roll", "<f4"),
    ("head", "<f4", (3,)), ("tail", "<f4", (3,)),
])
BINDING_RECORD = np.dtype([
    ("object", "<u4"), ("cache_key", "<u4"), ("kind", "<u4"), ("reserved", "<u4"),
    ("rigid_matrix", "<f8", (4, 4)),
])
SKIPPED_RECORD = np.dtype([
    ("mesh", "<u4"), ("cascade", "<u4"), ("span", "<f8"), ("dims", "<u4", (3,)),
    ("reserved", "<u4"),
])

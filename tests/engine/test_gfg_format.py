"""GFG files: write → read → write is byte-identical, arrays are zero-copy views, the container
rules (version, endianness, checksums, unknown sections) hold, and the CLI reports them."""
import pathlib
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
from gfg_scenes import full_scene
from meshes import box, tube
from snapshots import SkinData, mesh, snapshot, translation

from voxgi.voxgi_addon.files.gfg import (
    GFGError,
    RawSection,
    read_gfg,
    to_bytes,
    voxel_set_from_result,
    voxel_set_to_result,
    write_gfg,
)
from voxgi.voxgi_addon.files.gfg.model import GFGScene
from voxgi.voxgi_addon.files.gfg.spec import SECTION_REQUIRED
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]


def exactly_equal(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype.newbyteorder("=") == b.dtype.newbyteorder("=")
    if a.dtype.kind == "f":  # bit-exact, NaN included
        a, b = a.view(f"u{a.dtype.itemsize}"), b.view(f"u{b.dtype.itemsize}")
    assert np.array_equal(a, b)


def assert_scenes_equal(x: GFGScene, y: GFGScene):
    assert len(x.meshes) == len(y.meshes) and len(x.nodes) == len(y.nodes)
    for m, n in zip(x.meshes, y.meshes):
        assert (m.name, m.topology, m.skeleton, m.interleaved) == (n.name, n.topology, n.skeleton, n.interleaved)
        assert [(c.logic, c.data_type) for c in m.components] == [(c.logic, c.data_type) for c in n.components]
        for c, d in zip(m.components, n.components):
            exactly_equal(c.values, d.values)
        assert (m.indices is None) == (n.indices is None)
        if m.indices is not None:
            exactly_equal(m.indices, n.indices)
        assert m.ranges == n.ranges
        exactly_equal(m.aabb, n.aabb)
    for a, b in zip(x.nodes, y.nodes):
        assert (a.name, a.parent, a.kind, a.mesh, a.skeleton, a.armature_node) == \
            (b.name, b.parent, b.kind, b.mesh, b.skeleton, b.armature_node)
        for f in ("translation", "rotation", "scale", "parent_inverse", "world"):
            exactly_equal(getattr(a, f), getattr(b, f))
        assert (a.pose is None) == (b.pose is None)
        if a.pose is not None:
            for f in ("rotations", "locations", "scales"):
                exactly_equal(getattr(a.pose, f), getattr(b.pose, f))
    for a, b in zip(x.materials, y.materials):
        assert (a.name, a.logic, a.textures) == (b.name, b.logic, b.textures)
        assert list(a.uniforms) == list(b.uniforms)
        for k in a.uniforms:
            exactly_equal(a.uniforms[k], b.uniforms[k])
    for a, b in zip(x.skeletons, y.skeletons):
        assert (a.name, a.bone_names) == (b.name, b.bone_names)
        for f in ("parents", "flags", "heads", "tails", "rolls", "rest_matrices"):
            exactly_equal(np.asarray(getattr(a, f), getattr(b, f).dtype), getattr(b, f))
    for a, b in zip(x.animations, y.animations):
        assert (a.name, a.skeleton, a.node, a.hip_bone, a.layout) == (b.name, b.skeleton, b.node, b.hip_bone, b.layout)
        for f in ("times", "rotations", "hip_translations"):
            exactly_equal(getattr(a, f), getattr(b, f))
    if x.voxels is not None:
        assert (x.voxels.base_span, x.voxels.cascade_count, x.voxels.keys) == \
            (y.voxels.base_span, y.voxels.cascade_count, y.voxels.keys)
        assert x.voxels.skipped == y.voxels.skipped
        assert list(x.voxels.bindings) == list(y.voxels.bindings)
        for k, b in x.voxels.bindings.items():
            assert (b.cache_key, b.kind) == (y.voxels.bindings[k].cache_key, y.voxels.bindings[k].kind)
            exactly_equal(b.rigid_matrix, y.voxels.bindings[k].rigid_matrix)
        for c, d in zip(x.voxels.caches, y.voxels.caches):
            assert (c.key, c.cascade, c.span, c.skinned) == (d.key, d.cascade, d.span, d.skinned)
            for f in ("origin_cell", "dims", "positions", "normals", "colors", "weights", "bone_indices"):
                if getattr(c, f) is not None:
                    assert np.array_equal(getattr(c, f), getattr(d, f))
    for g, h in zip(x.probe_grids, y.probe_grids):
        for f in ("origin", "volume_size", "dims", "positions", "sh", "volume_cells", "volume_probes",
                  "volume_masks", "sh_index", "mask_index", "validity", "flags"):
            exactly_equal(np.asarray(getattr(g, f), np.asarray(getattr(h, f)).dtype), getattr(h, f))


@pytest.fixture(scope="module")
def scene():
    s = full_scene()
    s.extra_sections = []
    return s


def test_write_read_write_is_byte_identical_and_values_are_exact(scene, tmp_path):
    data = to_bytes(scene)
    path = tmp_path / "scene.gfg"
    assert write_gfg(path, scene) == len(data) == path.stat().st_size
    for source in (data, path):
        back = read_gfg(source)
        assert back.version == (1, 2)
        assert_scenes_equal(scene, back)
        assert to_bytes(back) == data


def test_arrays_map_the_buffer_without_copies_at_aligned_offsets(scene):
    data = bytearray(to_bytes(scene))
    base = np.frombuffer(data, np.uint8)
    back = read_gfg(data)
    arrays = [c.values for m in back.meshes for c in m.components] + \
        [m.indices for m in back.meshes if m.indices is not None] + \
        [a for c in back.voxels.caches for a in (c.positions, c.normals, c.colors)] + \
        [back.animations[0].rotations, back.skeletons[0].rest_matrices, back.probe_grids[0].sh]
    for a in arrays:
        assert np.shares_memory(a, base)
        assert not a.flags.owndata
    for c in back.voxels.caches:  # starts of typed arrays sit on 64-byte file offsets
        assert (c.positions.ctypes.data - base.ctypes.data) % 64 == 0
    assert (back.meshes[0].indices.ctypes.data - base.ctypes.data) % 64 == 0
    mapped = read_gfg(bytes(data))
    assert not mapped.voxels.caches[0].positions.flags.writeable


def _reseal_header(data: bytearray) -> bytearray:
    data[60:64] = struct.pack("<I", zlib.crc32(bytes(data[:60])))
    return data


def _reseal_table(data: bytearray) -> bytearray:
    count, = struct.unpack_from("<I", data, 32)
    data[36:40] = struct.pack("<I", zlib.crc32(bytes(data[64:64 + 32 * count])))
    return _reseal_header(data)


def test_version_endianness_and_checksums_are_enforced(scene):
    data = to_bytes(scene)
    newer_minor = bytearray(data)
    newer_minor[10:12] = struct.pack("<H", 7)
    assert read_gfg(_reseal_header(newer_minor)).version == (1, 7)
    newer_major = bytearray(data)
    newer_major[8:10] = struct.pack("<H", 2)
    with pytest.raises(GFGError, match="version_major"):
        read_gfg(_reseal_header(newer_major))
    big_endian = bytearray(data)
    big_endian[4:8] = struct.pack(">I", 0x0A0B0C0D)
    with pytest.raises(GFGError, match="little-endian"):
        read_gfg(_reseal_header(big_endian))
    flipped = bytearray(data)
    flipped[-3] ^= 0x10  # inside the last section (PRBG), in its last array (PROBE_FLAGS)
    with pytest.raises(GFGError, match=r"section 13 PRBG: crc"):
        read_gfg(bytes(flipped))
    # Without the checksums the probe flags' undefined bits still give it away.
    with pytest.raises(GFGError, match=r"section 13 PRBG: array PROBE_FLAGS: probe \d+ has undefined"):
        read_gfg(bytes(flipped), verify=False)
    with pytest.raises(GFGError, match="header: magic"):
        read_gfg(b"glTF" + data[4:])
    with pytest.raises(GFGError, match="truncated"):
        read_gfg(data[:-1])


def as_format_1_0(data: bytes) -> bytearray:
    """The same scene as the 1.0 writer wrote it: 1.1 changed no layout, only the version and the
    rule that padding and reserved bytes are zero (docs/gfg.md, "Every byte is checked")."""
    old = bytearray(data)
    old[10:12] = struct.pack("<H", 0)
    return _reseal_header(old)


def test_files_of_the_previous_version_1_0_are_still_read(scene, tmp_path):
    data = to_bytes(scene)
    assert struct.unpack_from("<HH", data, 8) == (1, 2)
    old = as_format_1_0(data)
    back = read_gfg(bytes(old))
    assert back.version == (1, 0)
    assert_scenes_equal(scene, back)
    # 1.0 did not promise zero padding, so its reader path does not check it; 1.1 refuses it.
    strg_offset, strg_size = struct.unpack_from("<QQ", data, 64 + 8)
    pad = strg_offset + strg_size  # the first padding byte after STRG
    assert pad < struct.unpack_from("<Q", data, 96 + 8)[0]

    def garbage(file: bytes) -> bytearray:
        damaged = bytearray(file)
        damaged[pad] = 0x77
        damaged[64 + 28] = 0x01  # table entry 0: reserved
        return _reseal_table(damaged)

    assert read_gfg(bytes(garbage(old))).version == (1, 0)
    new = garbage(data)
    with pytest.raises(GFGError, match=r"section table entry 0: reserved: 0x1 is not 0"):
        read_gfg(bytes(new))
    new[64 + 28] = 0
    with pytest.raises(GFGError, match=rf"padding after section 0 STRG: padding: byte at file offset {pad} "
                                       r"is 0x77, not 0"):
        read_gfg(bytes(_reseal_table(new)))
    path = tmp_path / "old.gfg"
    path.write_bytes(bytes(old))
    ok = _cli("verify", path)
    assert ok.returncode == 0 and "GFG 1.0" in ok.stdout and "padding is not checked" in ok.stdout


def test_unknown_sections_are_skipped_unless_required(scene):
    extra = GFGScene(**{**scene.__dict__, "extra_sections": [RawSection(b"FUTR", b"\x01\x02\x03")]})
    back = read_gfg(to_bytes(extra))
    assert [(s.kind, s.size) for s in back.skipped_sections] == [(b"FUTR", 3)]
    assert_scenes_equal(scene, back)
    required = GFGScene(**{**scene.__dict__,
                           "extra_sections": [RawSection(b"ZSTD", b"", flags=SECTION_REQUIRED)]})
    with pytest.raises(GFGError, match="ZSTD.*required but unknown"):
        read_gfg(to_bytes(required))


def test_a_wrong_cross_reference_names_section_and_field(scene):
    bad = full_scene()
    bad.extra_sections = []
    bad.nodes[1].mesh = 9
    with pytest.raises(GFGError, match=r"section 1 NODE: node 1 mesh: 9 is not in \[0, 4\)"):
        read_gfg(to_bytes(bad))
    bad = full_scene()
    bad.meshes[0].components[0].values = bad.meshes[0].components[0].values.astype(np.float64)
    with pytest.raises(GFGError, match="mesh 'Box': component 0 values"):
        to_bytes(bad)


def test_an_engine_voxelization_round_trips_through_a_voxel_set():
    v, t = box()
    tv, tt = tube(rings=5, segments=8, length=1.0)
    weights = np.zeros((len(tv), 4), np.float32)
    weights[:, 0] = 1.0
    skin = SkinData(weights, np.zeros((len(tv), 4), np.uint8), "Rig")
    snap = snapshot([mesh("Box", v, t), mesh("Tube", tv, tt, skin=skin)],
                    [("Box", "Box", translation(1.0)), ("Box.001", "Box", translation(-1.0, scale=(2, 2, 2))),
                     ("Tube", "Tube", np.eye(4), "skinned", "Rig")])
    result = build_scene_caches(snap, base_span=0.25, cascade_count=2)
    scene = GFGScene(voxels=voxel_set_from_result(result))
    back = voxel_set_to_result(read_gfg(to_bytes(scene)).voxels)
    assert list(back.caches) == list(result.caches)
    for key, caches in result.caches.items():
        for c, d in zip(caches, back.caches[key]):
            assert (c is None) == (d is None)
            if c is not None:
                assert (c.cascade, c.span, c.skinned) == (d.cascade, d.span, d.skinned)
                for f in ("origin_cell", "dims", "positions", "normals", "colors", "weights", "bone_indices"):
                    assert np.array_equal(getattr(c, f), getattr(d, f)) if getattr(c, f) is not None \
                        else getattr(d, f) is None
    assert back.cascade_stats == result.cascade_stats
    assert list(back.bindings) == list(result.bindings)
    assert [b.cache_key for b in back.bindings.values()] == [b.cache_key for b in result.bindings.values()]


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "voxgi_addon.files.gfg", *map(str, args)], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=60)


def test_command_line_info_and_verify(scene, tmp_path):
    path = tmp_path / "scene.gfg"
    write_gfg(path, scene)
    info = _cli("info", path)
    assert info.returncode == 0, info.stderr
    assert "GFG 1.2" in info.stdout and "14 sections" in info.stdout
    assert "'Box': 36 vertices, 36 indices (uint16), 3 material ranges" in info.stdout
    assert "'Skin' cascade 0 (span 0.25 m): 40 voxels, skinned" in info.stdout
    assert "15 probes (" in info.stdout and "2 active volumes of 2×2×2 (0.5×0.5×0.75 m)" in info.stdout
    ok = _cli("verify", path)
    assert ok.returncode == 0 and "OK" in ok.stdout
    data = bytearray(path.read_bytes())
    data[-3] ^= 1
    path.write_bytes(bytes(data))
    bad = _cli("verify", path)
    assert bad.returncode == 1 and "section 13 PRBG: crc" in bad.stdout
    missing = _cli("info", tmp_path / "nope.gfg")
    assert missing.returncode == 2 and "nope.gfg: cannot read: No such file" in missing.stderr
    assert "Traceback" not in missing.stderr


def test_additions_of_a_newer_minor_version_are_read_past(scene):
    """Longer info structs and unknown array roles (what a 1.x writer may add) are ignored."""
    import io

    from voxgi.voxgi_addon.files.gfg.container import write_container
    from voxgi.voxgi_addon.files.gfg.writer import build_sections

    sections = build_sections(scene)
    for s in sections:
        longer = np.zeros(1, np.dtype(s.info.dtype.descr + [("added_in_1_1", "<u8")]))
        for name in s.info.dtype.names:
            longer[name] = s.info[name]
        longer["added_in_1_1"] = 0xDEADBEEF
        s.info = longer
        s.add(99, 4, np.arange(7, dtype="<f4"))  # role 99: FLOAT_1 × 7
    stream = io.BytesIO()
    write_container(stream, sections)
    assert_scenes_equal(scene, read_gfg(stream.getvalue()))

"""The VOXGI_irradiance_volumes format without Blender (docs/gltf_probes.md): grids written by
``add_volumes`` into .glb, .gltf + .bin and embedded .gltf read back equal bit for bit; every
kind of damage — counts, indices, offsets, sizes, missing or mistyped fields, truncated files —
raises ``GltfProbesError`` naming the volume and the field, and random damage never raises
anything else."""
import copy
import json
import math
import struct

import numpy as np
import probe_scenes
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from voxgi.voxgi_addon.files import gltf_probes as fmt
from voxgi.voxgi_addon.probes.bake import ProbeSettings, bake_probe_grid
from voxgi.voxgi_addon.probes.grid import ProbeGrid

EXT = fmt.EXTENSION


@pytest.fixture(scope="module")
def grids():
    box = bake_probe_grid(probe_scenes.cornell_box(), ProbeSettings(resolution=3, directions=32)).grid
    box.name = "Box"
    wall = bake_probe_grid(probe_scenes.thin_wall_room(), ProbeSettings(resolution=4, directions=32)).grid
    wall.name = "Thin Wall"
    assert box.flags.any() and len(box.volume_cells) > 0 and (box.volume_masks >> np.uint64(32)).any()
    return [box, wall]


def assert_same(a: ProbeGrid, b: ProbeGrid):
    for key, value in vars(b).items():
        got = getattr(a, key)
        if isinstance(value, np.ndarray):
            assert got.dtype == value.dtype and got.shape == value.shape, key
            assert np.array_equal(got, value), key
        else:
            assert type(got) is type(value) and got == value, key


def written(grids):
    document, binary = fmt.new_document(), bytearray()
    fmt.add_volumes(document, binary, grids)
    return document, binary


def decode(document, binary):
    return fmt.decode_volumes(fmt.GltfFile(document, lambda i: bytes(binary) if i == 0 else None))


@pytest.mark.parametrize("suffix, embed", [(".glb", False), (".gltf", False), (".gltf", True)])
def test_grids_read_back_bit_for_bit(grids, tmp_path, suffix, embed):
    document, binary = written(grids)
    path = tmp_path / f"probes{suffix}"
    fmt.write_gltf(path, document, binary, embed=embed)
    assert (tmp_path / "probes.bin").exists() == (suffix == ".gltf" and not embed)
    volumes = fmt.read_volumes(path)
    assert [v.index for v in volumes] == [0, 1]
    for volume, grid in zip(volumes, grids):
        assert_same(volume.grid, grid)
        np.testing.assert_allclose(fmt.node_world_matrix(document, volume.node)[:3, :3],
                                   [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-15)


def test_the_layout_is_the_documented_one(grids):
    document, binary = written(grids[:1])
    grid = grids[0]
    p, v = len(grid.positions), len(grid.volume_cells)
    volume = document["extensions"][EXT]["volumes"][0]
    assert document["extensionsUsed"] == [EXT] and "extensionsRequired" not in document
    assert document["nodes"][volume["node"]]["extensions"][EXT] == {"volume": 0}
    assert volume["dims"] == grid.dims.tolist() and volume["origin"] == grid.origin.tolist()
    assert (volume["subdivisions"], volume["probeCount"], volume["activeVolumeCount"]) == (4, p, v)
    for name, kind, count in (("positions", "VEC3", p), ("sh", "VEC3", 9 * p), ("validity", "SCALAR", p)):
        accessor = document["accessors"][volume[name]]
        assert (accessor["componentType"], accessor["type"], accessor["count"]) == (5126, kind, count)
    for name, words in (("flags", p), ("volumeCells", v), ("volumeProbes", 8 * v), ("volumeMasks", 16 * v)):
        view = document["bufferViews"][volume[name]]
        assert view["byteLength"] == 4 * words and view["byteOffset"] % 4 == 0
        assert "byteStride" not in view and "target" not in view
    # masks: low word then high word of each corner's 64-bit mask; sh: probe-major, RGB per coefficient
    view = document["bufferViews"][volume["volumeMasks"]]
    words = np.frombuffer(binary, "<u4", 16 * v, view["byteOffset"]).reshape(v, 8, 2)
    masks = grid.volume_masks
    assert np.array_equal(words[..., 0], masks & np.uint64(0xFFFFFFFF))
    assert np.array_equal(words[..., 1], masks >> np.uint64(32))
    view = document["bufferViews"][document["accessors"][volume["sh"]]["bufferView"]]
    sh = np.frombuffer(binary, "<f4", 27 * p, view["byteOffset"])
    assert sh[(9 * 2 + 4) * 3 + 1] == grid.sh[2, 4, 1]


def test_a_grid_without_active_volumes_has_no_arrays(tmp_path):
    grid = ProbeGrid(origin=[0, 0, 0], volume_size=[1, 2, 3], dims=[2, 1, 1],
                     positions=np.zeros((0, 3), np.float32), sh=np.zeros((0, 9, 3), np.float32),
                     volume_cells=np.zeros(0, np.uint32), volume_probes=np.zeros((0, 8), np.uint32),
                     volume_masks=np.zeros((0, 8), np.uint64), mask_threshold=0.0, name="")
    document, binary = written([grid])
    volume = document["extensions"][EXT]["volumes"][0]
    assert not set(volume) & {"positions", "sh", "validity", "flags", "volumeCells"}
    assert document["nodes"][0]["name"] == "VoxGI Volume 0"
    path = tmp_path / "empty.glb"
    fmt.write_gltf(path, document, binary)
    assert_same(fmt.read_volumes(path)[0].grid, grid)


def test_the_writer_refuses_what_the_format_cannot_hold(grids):
    bad = copy.deepcopy(grids[0])
    bad.sh = bad.sh[:-1]
    with pytest.raises(fmt.GltfProbesError, match="volume 0 'Box': sh: shape"):
        fmt.encode_grid(bad)
    bad = copy.deepcopy(grids[0])
    bad.positions[3, 1] = np.nan
    with pytest.raises(fmt.GltfProbesError, match="positions: holds NaN"):
        fmt.encode_grid(bad)


def test_node_transforms_compose():
    document = {"nodes": [{"children": [1], "translation": [1, 2, 3], "scale": [2, 2, 2]},
                          {"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1]}]}
    m = fmt.node_world_matrix(document, 1)
    np.testing.assert_allclose(m @ [0, 0, 0, 1], [11, 2, 3, 1])
    document["nodes"][1]["children"] = [0]
    with pytest.raises(fmt.GltfProbesError, match="cycle"):
        fmt.node_world_matrix(document, 1)


# ------------------------------------------------------------------------------- bad input

def _volume(d):
    return d["extensions"][EXT]["volumes"][0]


def _view(d, field):
    return d["bufferViews"][_volume(d)[field]]


def _accessor(d, field):
    return d["accessors"][_volume(d)[field]]


def _poke(d, b, field, word, value):
    offset = _view(d, field)["byteOffset"] + 4 * word
    b[offset:offset + 4] = struct.pack("<I", value)


def _poke_float(d, b, field, index, value):
    offset = d["bufferViews"][_accessor(d, field)["bufferView"]]["byteOffset"] + 4 * index
    b[offset:offset + 4] = struct.pack("<f", value)


def _probe_elsewhere(d, b):
    """A probe of the grid that is not volume 0's corner 0 (volume 0's corner 7)."""
    view = _view(d, "volumeProbes")
    return struct.unpack_from("<I", b, view["byteOffset"] + 4 * 7)[0]


BAD = {
    "probe index out of range": (lambda d, b: _poke(d, b, "volumeProbes", 5, 10**6), "volumeProbes", "out of range"),
    "volume outside the grid": (lambda d, b: _poke(d, b, "volumeCells", 0, 10**6), "volumeCells", "outside"),
    "volumes not ascending": (lambda d, b: _poke(d, b, "volumeCells", 1, 0), "volumeCells", "ascending"),
    "validity above 1": (lambda d, b: _poke_float(d, b, "validity", 2, 1.5), "validity", "[0, 1]"),
    "two probes at one corner": (lambda d, b: _poke(d, b, "volumeProbes", 0, _probe_elsewhere(d, b)),
                                 "volumeProbes", "corner"),
    "unknown flag bits": (lambda d, b: _poke(d, b, "flags", 0, 8), "flags", "unknown bits"),
    "NaN coefficient": (lambda d, b: _poke_float(d, b, "sh", 7, math.nan), "sh", "NaN"),
    "positions count": (lambda d, b: _accessor(d, "positions").update(count=3), "positions", "count is 3"),
    "sh count": (lambda d, b: _accessor(d, "sh").update(count=9), "sh", "9 × probeCount"),
    "probeCount": (lambda d, b: _volume(d).update(probeCount=_volume(d)["probeCount"] - 1), "positions", "probeCount"),
    "activeVolumeCount": (lambda d, b: _volume(d).update(activeVolumeCount=_volume(d)["activeVolumeCount"] + 1),
                          "volumeCells", "activeVolumeCount"),
    "accessor index": (lambda d, b: _volume(d).update(sh=999), "sh", "out of range"),
    "accessor index type": (lambda d, b: _volume(d).update(sh="0"), "sh", "must be an index"),
    "bufferView index": (lambda d, b: _volume(d).update(volumeMasks=-1), "volumeMasks", "out of range"),
    "component type": (lambda d, b: _accessor(d, "validity").update(componentType=5123), "validity", "componentType"),
    "accessor type": (lambda d, b: _accessor(d, "positions").update(type="VEC4"), "positions", "type"),
    "sparse accessor": (lambda d, b: _accessor(d, "sh").update(sparse={}), "sh", "sparse"),
    "bufferView past the buffer": (lambda d, b: _view(d, "volumeMasks").update(byteLength=10**6), "volumeMasks",
                                   "runs past"),
    "bufferView length": (lambda d, b: _view(d, "volumeProbes").update(
        byteLength=_view(d, "volumeProbes")["byteLength"] - 4), "volumeProbes", "expected"),
    "bufferView misaligned": (lambda d, b: _view(d, "flags").update(byteOffset=_view(d, "flags")["byteOffset"] + 2),
                              "flags", "multiple of 4"),
    "bufferView stride": (lambda d, b: _view(d, "volumeCells").update(byteStride=8), "volumeCells", "byteStride"),
    "accessor past its view": (lambda d, b: _accessor(d, "validity").update(byteOffset=64), "validity", "needs"),
    "buffer shorter than declared": (lambda d, b: b.__delitem__(slice(len(b) - 64, None)), "", "holds"),
    "dims zero": (lambda d, b: _volume(d).update(dims=[3, 0, 3]), "dims", "≥ 1"),
    "dims negative": (lambda d, b: _volume(d).update(dims=[-3, 3, 3]), "dims", "≥ 1"),
    "dims not integers": (lambda d, b: _volume(d).update(dims=[3.0, 3, 3]), "dims", "3 integers"),
    "dims huge": (lambda d, b: _volume(d).update(dims=[4096, 4096, 4096]), "dims", "grid corners"),
    "dims missing": (lambda d, b: _volume(d).pop("dims"), "dims", "3 integers"),
    "origin missing": (lambda d, b: _volume(d).pop("origin"), "origin", "3 finite numbers"),
    "volumeSize zero": (lambda d, b: _volume(d).update(volumeSize=[1, 0, 1]), "volumeSize", "> 0"),
    "subdivisions": (lambda d, b: _volume(d).update(subdivisions=8), "subdivisions", "must be 4"),
    "maskThreshold": (lambda d, b: _volume(d).update(maskThreshold=2), "maskThreshold", "[0, 1]"),
    "sh missing": (lambda d, b: _volume(d).pop("sh"), "sh", "missing"),
    "probeCount missing": (lambda d, b: _volume(d).pop("probeCount"), "probeCount", "integer ≥ 0"),
    "name not a string": (lambda d, b: _volume(d).update(name=3), "name", "string"),
    "node out of range": (lambda d, b: _volume(d).update(node=99), "node", "out of range"),
    "node without back-reference": (lambda d, b: d["nodes"][_volume(d)["node"]].pop("extensions"), "node",
                                    "point back"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_damage_is_reported_with_the_volume_and_the_field(grids, case):
    change, field, words = BAD[case]
    document, binary = written(grids[:1])
    change(document, binary)
    with pytest.raises(fmt.GltfProbesError) as raised:
        decode(document, binary)
    message = str(raised.value)
    where = "volume 0" if case == "name not a string" else "volume 0 'Box'"
    assert message.startswith(f"{where}: {field}") and words in message, message


def test_a_truncated_glb_and_a_missing_bin_are_reported(grids, tmp_path):
    document, binary = written(grids[:1])
    path = tmp_path / "probes.glb"
    fmt.write_gltf(path, document, binary)
    data = path.read_bytes()
    cut = tmp_path / "cut.glb"
    cut.write_bytes(data[:len(data) - 100])
    with pytest.raises(fmt.GltfProbesError, match="GLB header"):
        fmt.read_volumes(cut)
    # a GLB whose header was fixed up after the cut: the BIN chunk runs past the file
    cut.write_bytes(data[:8] + struct.pack("<I", len(data) - 100) + data[12:len(data) - 100])
    with pytest.raises(fmt.GltfProbesError, match="BIN chunk"):
        fmt.read_volumes(cut)
    fmt.write_gltf(tmp_path / "split.gltf", document, binary)
    (tmp_path / "split.bin").unlink()
    with pytest.raises(fmt.GltfProbesError, match=r"volume 0 'Box': positions .*buffers\[0\] cannot be read"):
        fmt.read_volumes(tmp_path / "split.gltf")
    (tmp_path / "text.gltf").write_text("{not json")
    with pytest.raises(fmt.GltfProbesError, match="JSON"):
        fmt.read_volumes(tmp_path / "text.gltf")


def test_a_root_extension_of_the_wrong_shape_is_reported(grids):
    document, binary = written(grids[:1])
    document["extensions"][EXT] = {"volume": []}
    with pytest.raises(fmt.GltfProbesError, match="'volumes' array"):
        decode(document, binary)
    document["extensions"][EXT] = {"volumes": [7]}
    with pytest.raises(fmt.GltfProbesError, match="volume 0: volume: is not an object"):
        decode(document, binary)
    assert decode({"asset": {"version": "2.0"}}, b"") == []


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-2**40, 2**40) | st.floats(allow_nan=False, allow_infinity=True)
    | st.text(max_size=4),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=4), children, max_size=3),
    max_leaves=8)
FIELDS = ["name", "node", "dims", "origin", "volumeSize", "subdivisions", "maskThreshold", "probeCount",
          "activeVolumeCount", "positions", "sh", "validity", "flags", "volumeCells", "volumeProbes", "volumeMasks"]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.lists(st.tuples(st.sampled_from(FIELDS), JSON_VALUES), min_size=1, max_size=3),
       flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), max_size=4),
       cut=st.integers(0, 200))
def test_random_damage_raises_only_gltf_probes_errors(grids, changes, flips, cut):
    document, binary = written(grids[:1])
    document = json.loads(json.dumps(document))
    for key, value in changes:
        _volume(document)[key] = value
    for at, mask in flips:
        binary[at % len(binary)] ^= mask
    if cut:
        del binary[len(binary) - cut:]
    try:
        volumes = decode(document, binary)
    except fmt.GltfProbesError:
        return
    grid = volumes[0].grid  # what decodes is a usable grid
    p = len(grid.positions)
    assert grid.sh.shape == (p, 9, 3) and np.isfinite(grid.sh).all()
    assert (grid.volume_probes < max(p, 1)).all() and (grid.volume_cells < grid.dims.prod()).all()


def test_the_schema_lists_what_the_writer_writes(grids):
    schemas = fmt.__file__.replace("voxgi_addon/files/gltf_probes.py", "docs/schema/")
    volume_schema = json.load(open(schemas + "volume.schema.json"))
    root_schema = json.load(open(schemas + "VOXGI_irradiance_volumes.schema.json"))
    node_schema = json.load(open(schemas + "node.VOXGI_irradiance_volumes.schema.json"))
    document, _ = written(grids[:1])
    volume = document["extensions"][EXT]["volumes"][0]
    properties = volume_schema["properties"]
    assert set(volume) <= set(properties) and set(volume_schema["required"]) <= set(volume)
    assert set(properties) - {"extensions", "extras"} == set(volume)  # every property is written
    assert properties["subdivisions"]["const"] == volume["subdivisions"] == fmt.SUBDIVISIONS
    conditional = [part for part in volume_schema["allOf"] if "if" in part]
    assert {tuple(part["then"]["required"]) for part in conditional} == {
        tuple(fmt.ACCESSORS) + ("flags",), ("volumeCells", "volumeProbes", "volumeMasks")}
    assert set(document["extensions"][EXT]) == set(root_schema["required"])
    node = document["nodes"][volume["node"]]["extensions"][EXT]
    assert set(node) == set(node_schema["required"])

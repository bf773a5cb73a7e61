"""Base Colors that vary per object through Object Info › Random (main thread only).

Scattering one mesh many times and colouring each copy by Object Info › Random through a
Color Ramp, a Mix or a Hue/Saturation node is how artists vary rocks, leaves and crowds. A
bake over the mesh's UV map gives every copy one colour (the bake object's own Random), so
such a Base Color is evaluated here per object instead: ``random_base_color(material)``
returns the socket as a function of the Random value where it depends on Random alone
through the nodes below, and ``object_random`` gives an object's value as Cycles computes it
(docs/blender_facts.md "Object Info › Random").

Nodes followed: Object Info (Random), Color Ramp (``ColorRamp.evaluate``), Mix (Color
and Float, Mix blending), MixRGB (Mix), Math (the common operations), Map Range (Linear,
Stepped), Clamp, Hue/Saturation/Value, Invert, RGB, Value, Combine / Separate Color (RGB),
reroutes. Anything else (a texture, a UV, another Object Info output) leaves the socket to
the other ways of ``materials.py``.
"""
from __future__ import annotations

import colorsys
import functools
import math

import numpy as np

from .node_groups import surface_node
from .world_map import _follow, _NeedsBake

__all__ = ["object_random", "random_base_color"]

_M32 = 0xFFFFFFFF
LUMINANCE = (0.2126, 0.7152, 0.0722)  # Cycles' colour → float conversion (Rec.709)


class _NotRandom(Exception):
    """The socket does not depend on Random alone through nodes followed here."""


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M32


def hash_uint2(kx: int, ky: int) -> int:
    """Cycles' ``hash_uint2`` (Bob Jenkins' lookup3 final mix of two words)."""
    a = b = c = (0xDEADBEEF + (2 << 2) + 13) & _M32
    b = (b + ky) & _M32
    a = (a + kx) & _M32
    c ^= b
    c = (c - _rot(b, 14)) & _M32
    a ^= c
    a = (a - _rot(c, 11)) & _M32
    b ^= a
    b = (b - _rot(a, 25)) & _M32
    c ^= b
    c = (c - _rot(b, 16)) & _M32
    a ^= c
    a = (a - _rot(c, 4)) & _M32
    b ^= a
    b = (b - _rot(a, 14)) & _M32
    c ^= b
    return (c - _rot(b, 24)) & _M32


def hash_string(text: str) -> int:
    """Cycles' ``hash_string``: i = i × 37 + byte over the UTF-8 bytes, in 32 bits."""
    value = 0
    for byte in text.encode("utf-8"):
        value = (value * 37 + byte) & _M32
    return value


@functools.lru_cache(maxsize=1 << 16)
def object_random(name: str, random_id: int | None = None) -> float:
    """Object Info › Random of an object as Cycles renders it: an instance's (collection,
    particle or geometry-nodes instance) ``DepsgraphObjectInstance.random_id`` over 2³² − 1;
    an object of the view layer's, its name hashed (``hash_uint2(hash_string(name), 0)``)."""
    if random_id is None:
        random_id = hash_uint2(hash_string(name), 0)
    return (int(random_id) & _M32) / _M32


def random_base_color(material):
    """A function random → (3,) float32 linear RGB of the material's Principled BSDF Base
    Color where it depends on Object Info › Random alone (module doc), else None."""
    tree = material.node_tree if material is not None else None
    node = None if tree is None else surface_node(tree, "BSDF_PRINCIPLED")
    if node is None:
        return None
    socket = node.inputs["Base Color"]
    if not socket.is_linked:
        return None
    try:
        _, reads = _colour(socket, 0.5, 0)
    except (_NotRandom, _NeedsBake, KeyError, IndexError, AttributeError, ValueError,
            ZeroDivisionError, OverflowError):
        return None
    if not reads:
        return None  # no Random on the way: a constant, baked or read as before

    def base_color(random: float) -> np.ndarray:
        colour, _ = _colour(socket, float(random), 0)
        return np.clip(np.asarray(colour[:3], np.float32), 0.0, None)

    return base_color


# ---------------------------------------------------------------------- evaluation
# Each returns (value, whether Random was read): colours as 3-tuples, floats as floats.

def _input(socket, random: float, depth: int):
    """An input socket's value: its default when unlinked, else its source output's."""
    if depth > 32:
        raise _NotRandom("too deep")
    if not socket.is_linked:
        value = socket.default_value
        try:
            return tuple(float(v) for v in value), False
        except TypeError:
            return float(value), False
    node, output = _follow(socket)
    if node is None:
        raise _NotRandom("a muted link")
    return _output(node, output, random, depth + 1)


def _colour(socket, random, depth):
    value, reads = _input(socket, random, depth)
    if isinstance(value, float):
        return (value, value, value), reads
    return tuple(value[:3]), reads


def _float(socket, random, depth):
    value, reads = _input(socket, random, depth)
    if isinstance(value, float):
        return value, reads
    return sum(w * c for w, c in zip(LUMINANCE, value[:3])), reads


def _socket(node, identifier):
    return next(s for s in node.inputs if s.identifier == identifier and s.enabled)


def _output(node, output, random, depth):
    kind = node.type
    name = output.identifier
    if kind == "OBJECT_INFO":
        if name != "Random":
            raise _NotRandom(f"Object Info › {name}")
        return float(random), True
    if kind == "VALUE":
        return float(output.default_value), False
    if kind == "RGB":
        return tuple(float(v) for v in output.default_value[:3]), False
    if kind == "VALTORGB":
        fac, reads = _float(node.inputs["Fac"], random, depth)
        rgba = node.color_ramp.evaluate(min(max(fac, 0.0), 1.0))
        return (float(rgba[3]) if name == "Alpha" else tuple(float(v) for v in rgba[:3])), reads
    if kind == "MIX":
        return _mix(node, name, random, depth)
    if kind == "MIX_RGB":
        if node.blend_type != "MIX":
            raise _NotRandom(f"MixRGB {node.blend_type}")
        fac, r0 = _float(node.inputs["Fac"], random, depth)
        a, r1 = _colour(node.inputs["Color1"], random, depth)
        b, r2 = _colour(node.inputs["Color2"], random, depth)
        fac = min(max(fac, 0.0), 1.0)
        out = tuple((1 - fac) * x + fac * y for x, y in zip(a, b))
        if node.use_clamp:
            out = tuple(min(max(v, 0.0), 1.0) for v in out)
        return out, r0 or r1 or r2
    if kind == "MATH":
        return _math(node, random, depth)
    if kind == "MAP_RANGE":
        return _map_range(node, random, depth)
    if kind == "CLAMP":
        value, r0 = _float(node.inputs["Value"], random, depth)
        low, r1 = _float(node.inputs["Min"], random, depth)
        high, r2 = _float(node.inputs["Max"], random, depth)
        if node.clamp_type == "RANGE" and low > high:
            low, high = high, low
        return min(max(value, low), high), r0 or r1 or r2
    if kind == "INVERT":
        fac, r0 = _float(node.inputs["Fac"], random, depth)
        colour, r1 = _colour(node.inputs["Color"], random, depth)
        return tuple((1 - fac) * c + fac * (1 - c) for c in colour), r0 or r1
    if kind == "HUE_SAT":
        return _hue_sat(node, random, depth)
    if kind == "COMBINE_COLOR":
        if node.mode != "RGB":
            raise _NotRandom(f"Combine Color {node.mode}")
        parts = [_float(node.inputs[k], random, depth) for k in ("Red", "Green", "Blue")]
        return tuple(v for v, _ in parts), any(r for _, r in parts)
    if kind == "SEPARATE_COLOR":
        if node.mode != "RGB":
            raise _NotRandom(f"Separate Color {node.mode}")
        colour, reads = _colour(node.inputs["Color"], random, depth)
        return colour[("Red", "Green", "Blue").index(name)], reads
    raise _NotRandom(f"a '{node.type}' node")


def _mix(node, name, random, depth):
    if node.data_type not in ("RGBA", "FLOAT") or node.blend_type != "MIX" or \
            node.factor_mode != "UNIFORM":
        raise _NotRandom("a Mix node this does not follow")
    fac, r0 = _float(_socket(node, "Factor_Float"), random, depth)
    if node.clamp_factor:
        fac = min(max(fac, 0.0), 1.0)
    if node.data_type == "FLOAT":
        a, r1 = _float(_socket(node, "A_Float"), random, depth)
        b, r2 = _float(_socket(node, "B_Float"), random, depth)
        return (1 - fac) * a + fac * b, r0 or r1 or r2
    a, r1 = _colour(_socket(node, "A_Color"), random, depth)
    b, r2 = _colour(_socket(node, "B_Color"), random, depth)
    out = tuple((1 - fac) * x + fac * y for x, y in zip(a, b))
    if node.clamp_result:
        out = tuple(min(max(v, 0.0), 1.0) for v in out)
    return out, r0 or r1 or r2


_MATH = {
    "ADD": lambda a, b, c: a + b,
    "SUBTRACT": lambda a, b, c: a - b,
    "MULTIPLY": lambda a, b, c: a * b,
    "DIVIDE": lambda a, b, c: a / b if b != 0.0 else 0.0,
    "MULTIPLY_ADD": lambda a, b, c: a * b + c,
    "POWER": lambda a, b, c: math.pow(a, b) if a > 0.0 or float(b).is_integer() else 0.0,
    "MINIMUM": lambda a, b, c: min(a, b),
    "MAXIMUM": lambda a, b, c: max(a, b),
    "ABSOLUTE": lambda a, b, c: abs(a),
    "FRACT": lambda a, b, c: a - math.floor(a),
    "FLOOR": lambda a, b, c: math.floor(a),
    "CEIL": lambda a, b, c: math.ceil(a),
    "ROUND": lambda a, b, c: math.floor(a + 0.5),
    "MODULO": lambda a, b, c: math.fmod(a, b) if b != 0.0 else 0.0,
    "SNAP": lambda a, b, c: math.floor(a / b) * b if b != 0.0 else 0.0,
    "GREATER_THAN": lambda a, b, c: 1.0 if a > b else 0.0,
    "LESS_THAN": lambda a, b, c: 1.0 if a < b else 0.0,
    "SINE": lambda a, b, c: math.sin(a),
}


def _math(node, random, depth):
    operation = _MATH.get(node.operation)
    if operation is None:
        raise _NotRandom(f"Math {node.operation}")
    values = [_float(s, random, depth) for s in node.inputs[:3]]
    out = float(operation(*(v for v, _ in values)))
    if node.use_clamp:
        out = min(max(out, 0.0), 1.0)
    return out, any(r for _, r in values)


def _map_range(node, random, depth):
    if node.data_type != "FLOAT" or node.interpolation_type not in ("LINEAR", "STEPPED"):
        raise _NotRandom("a Map Range this does not follow")
    names = ("Value", "From Min", "From Max", "To Min", "To Max")
    values = [_float(_socket(node, n), random, depth) for n in names]
    value, low, high, to_low, to_high = (v for v, _ in values)
    reads = any(r for _, r in values)
    if high == low:
        return 0.0, reads
    t = (value - low) / (high - low)
    if node.interpolation_type == "STEPPED":
        steps, r = _float(_socket(node, "Steps"), random, depth)
        reads = reads or r
        t = math.floor(t * steps) / steps if steps > 0.0 else 0.0
    out = to_low + t * (to_high - to_low)
    if node.clamp:
        out = min(max(out, min(to_low, to_high)), max(to_low, to_high))
    return out, reads


def _hue_sat(node, random, depth):
    hue, r0 = _float(node.inputs["Hue"], random, depth)
    sat, r1 = _float(node.inputs["Saturation"], random, depth)
    val, r2 = _float(node.inputs["Value"], random, depth)
    fac, r3 = _float(node.inputs["Fac"], random, depth)
    colour, r4 = _colour(node.inputs["Color"], random, depth)
    h, s, v = colorsys.rgb_to_hsv(*colour)
    h = (h + hue + 0.5) % 1.0
    s = min(max(s * sat, 0.0), 1.0)
    v = v * val
    shifted = colorsys.hsv_to_rgb(h, s, v)
    out = tuple(max(fac * x + (1 - fac) * c, 0.0) for x, c in zip(shifted, colour))
    return out, r0 or r1 or r2 or r3 or r4

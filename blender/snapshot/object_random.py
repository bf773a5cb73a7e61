"""Base Colors that vary per object through Object Info › Random or Color (main thread only).

Scattering one mesh many times and colouring each copy by Object Info › Random through a
Color Ramp, a Mix or a Hue/Saturation node is how artists vary rocks, leaves and crowds; a
script or a team's convention tints each copy by its object's Color (Object Properties ›
Viewport Display › Color) the same way. A bake over the mesh's UV map gives every copy one
colour (the bake object's own), so such a Base Color is evaluated here per object instead:
``object_base_color(material)`` returns the socket as a function of the object's
``ObjectInputs`` where it depends on them alone through the nodes below, and
``object_random`` gives an object's Random as Cycles computes it (docs/blender_facts.md
"Object Info › Random").

Nodes followed: Object Info (Random, Color, Alpha), Color Ramp (``ColorRamp.evaluate``), Mix (Color
and Float, Mix blending), MixRGB (Mix), Math (the common operations), Map Range (Linear,
Stepped), Clamp, Hue/Saturation/Value, Invert, RGB, Value, Combine / Separate Color (RGB),
reroutes. Anything else (a texture, a UV, Object Info's Location or indices) leaves the socket
to the other ways of ``materials.py``.
"""
from __future__ import annotations

import colorsys
import functools
import math
from typing import NamedTuple

import numpy as np

from .node_groups import surface_node
from .world_map import _follow, _NeedsBake

__all__ = ["ObjectInputs", "object_base_color", "object_random"]

_M32 = 0xFFFFFFFF
LUMINANCE = (0.2126, 0.7152, 0.0722)  # Cycles' colour → float conversion (Rec.709)


class _NotRandom(Exception):
    """The socket does not depend on Object Info and constants alone through nodes followed here."""


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


class ObjectInputs(NamedTuple):
    """What Object Info gives a material on one object: its Random and its Color (RGBA, the
    object's Viewport Display colour; Alpha its fourth value)."""

    random: float
    color: tuple = (1.0, 1.0, 1.0, 1.0)


_NONE: frozenset = frozenset()
_RANDOM = frozenset({"Random"})
_COLOR = frozenset({"Color"})


def object_base_color(material):
    """(function ObjectInputs → (3,) float32 linear RGB, whether it reads the object's Color)
    of the material's Principled BSDF Base Color where it depends on Object Info › Random,
    Color or Alpha and constants alone (module doc), else None."""
    tree = material.node_tree if material is not None else None
    node = None if tree is None else surface_node(tree, "BSDF_PRINCIPLED")
    if node is None:
        return None
    socket = node.inputs["Base Color"]
    if not socket.is_linked:
        return None
    try:
        _, reads = _colour(socket, ObjectInputs(0.5), 0)
    except (_NotRandom, _NeedsBake, KeyError, IndexError, AttributeError, ValueError,
            ZeroDivisionError, OverflowError):
        return None
    if not reads:
        return None  # no Object Info on the way: a constant, baked or read as before

    def base_color(inputs: ObjectInputs) -> np.ndarray:
        colour, _ = _colour(socket, inputs, 0)
        return np.clip(np.asarray(colour[:3], np.float32), 0.0, None)

    return base_color, "Color" in reads


# ---------------------------------------------------------------------- evaluation
# Each returns (value, the Object Info inputs read: _RANDOM, _COLOR): colours as 3-tuples,
# floats as floats. ``inputs``: the object's ``ObjectInputs``.

def _input(socket, inputs, depth: int):
    """An input socket's value: its default when unlinked, else its source output's."""
    if depth > 32:
        raise _NotRandom("too deep")
    if not socket.is_linked:
        value = socket.default_value
        try:
            return tuple(float(v) for v in value), _NONE
        except TypeError:
            return float(value), _NONE
    node, output = _follow(socket)
    if node is None:
        raise _NotRandom("a muted link")
    return _output(node, output, inputs, depth + 1)


def _colour(socket, inputs, depth):
    value, reads = _input(socket, inputs, depth)
    if isinstance(value, float):
        return (value, value, value), reads
    return tuple(value[:3]), reads


def _float(socket, inputs, depth):
    value, reads = _input(socket, inputs, depth)
    if isinstance(value, float):
        return value, reads
    return sum(w * c for w, c in zip(LUMINANCE, value[:3])), reads


def _socket(node, identifier):
    return next(s for s in node.inputs if s.identifier == identifier and s.enabled)


def _output(node, output, inputs, depth):
    kind = node.type
    name = output.identifier
    if kind == "OBJECT_INFO":
        if name == "Random":
            return float(inputs.random), _RANDOM
        if name == "Color":
            return tuple(float(c) for c in inputs.color[:3]), _COLOR
        if name == "Alpha":
            return float(inputs.color[3]), _COLOR
        raise _NotRandom(f"Object Info › {name}")
    if kind == "VALUE":
        return float(output.default_value), _NONE
    if kind == "RGB":
        return tuple(float(v) for v in output.default_value[:3]), _NONE
    if kind == "VALTORGB":
        fac, reads = _float(node.inputs["Fac"], inputs, depth)
        rgba = node.color_ramp.evaluate(min(max(fac, 0.0), 1.0))
        return (float(rgba[3]) if name == "Alpha" else tuple(float(v) for v in rgba[:3])), reads
    if kind == "MIX":
        return _mix(node, name, inputs, depth)
    if kind == "MIX_RGB":
        if node.blend_type != "MIX":
            raise _NotRandom(f"MixRGB {node.blend_type}")
        fac, r0 = _float(node.inputs["Fac"], inputs, depth)
        a, r1 = _colour(node.inputs["Color1"], inputs, depth)
        b, r2 = _colour(node.inputs["Color2"], inputs, depth)
        fac = min(max(fac, 0.0), 1.0)
        out = tuple((1 - fac) * x + fac * y for x, y in zip(a, b))
        if node.use_clamp:
            out = tuple(min(max(v, 0.0), 1.0) for v in out)
        return out, r0 | r1 | r2
    if kind == "MATH":
        return _math(node, inputs, depth)
    if kind == "MAP_RANGE":
        return _map_range(node, inputs, depth)
    if kind == "CLAMP":
        value, r0 = _float(node.inputs["Value"], inputs, depth)
        low, r1 = _float(node.inputs["Min"], inputs, depth)
        high, r2 = _float(node.inputs["Max"], inputs, depth)
        if node.clamp_type == "RANGE" and low > high:
            low, high = high, low
        return min(max(value, low), high), r0 | r1 | r2
    if kind == "INVERT":
        fac, r0 = _float(node.inputs["Fac"], inputs, depth)
        colour, r1 = _colour(node.inputs["Color"], inputs, depth)
        return tuple((1 - fac) * c + fac * (1 - c) for c in colour), r0 | r1
    if kind == "HUE_SAT":
        return _hue_sat(node, inputs, depth)
    if kind == "COMBINE_COLOR":
        if node.mode != "RGB":
            raise _NotRandom(f"Combine Color {node.mode}")
        parts = [_float(node.inputs[k], inputs, depth) for k in ("Red", "Green", "Blue")]
        return tuple(v for v, _ in parts), _NONE.union(*(r for _, r in parts))
    if kind == "SEPARATE_COLOR":
        if node.mode != "RGB":
            raise _NotRandom(f"Separate Color {node.mode}")
        colour, reads = _colour(node.inputs["Color"], inputs, depth)
        return colour[("Red", "Green", "Blue").index(name)], reads
    raise _NotRandom(f"a '{node.type}' node")


def _mix(node, name, inputs, depth):
    if node.data_type not in ("RGBA", "FLOAT") or node.blend_type != "MIX" or \
            node.factor_mode != "UNIFORM":
        raise _NotRandom("a Mix node this does not follow")
    fac, r0 = _float(_socket(node, "Factor_Float"), inputs, depth)
    if node.clamp_factor:
        fac = min(max(fac, 0.0), 1.0)
    if node.data_type == "FLOAT":
        a, r1 = _float(_socket(node, "A_Float"), inputs, depth)
        b, r2 = _float(_socket(node, "B_Float"), inputs, depth)
        return (1 - fac) * a + fac * b, r0 | r1 | r2
    a, r1 = _colour(_socket(node, "A_Color"), inputs, depth)
    b, r2 = _colour(_socket(node, "B_Color"), inputs, depth)
    out = tuple((1 - fac) * x + fac * y for x, y in zip(a, b))
    if node.clamp_result:
        out = tuple(min(max(v, 0.0), 1.0) for v in out)
    return out, r0 | r1 | r2


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


def _math(node, inputs, depth):
    operation = _MATH.get(node.operation)
    if operation is None:
        raise _NotRandom(f"Math {node.operation}")
    values = [_float(s, inputs, depth) for s in node.inputs[:3]]
    out = float(operation(*(v for v, _ in values)))
    if node.use_clamp:
        out = min(max(out, 0.0), 1.0)
    return out, _NONE.union(*(r for _, r in values))


def _map_range(node, inputs, depth):
    if node.data_type != "FLOAT" or node.interpolation_type not in ("LINEAR", "STEPPED"):
        raise _NotRandom("a Map Range this does not follow")
    names = ("Value", "From Min", "From Max", "To Min", "To Max")
    values = [_float(_socket(node, n), inputs, depth) for n in names]
    value, low, high, to_low, to_high = (v for v, _ in values)
    reads = _NONE.union(*(r for _, r in values))
    if high == low:
        return 0.0, reads
    t = (value - low) / (high - low)
    if node.interpolation_type == "STEPPED":
        steps, r = _float(_socket(node, "Steps"), inputs, depth)
        reads = reads | r
        t = math.floor(t * steps) / steps if steps > 0.0 else 0.0
    out = to_low + t * (to_high - to_low)
    if node.clamp:
        out = min(max(out, min(to_low, to_high)), max(to_low, to_high))
    return out, reads


def _hue_sat(node, inputs, depth):
    hue, r0 = _float(node.inputs["Hue"], inputs, depth)
    sat, r1 = _float(node.inputs["Saturation"], inputs, depth)
    val, r2 = _float(node.inputs["Value"], inputs, depth)
    fac, r3 = _float(node.inputs["Fac"], inputs, depth)
    colour, r4 = _colour(node.inputs["Color"], inputs, depth)
    h, s, v = colorsys.rgb_to_hsv(*colour)
    h = (h + hue + 0.5) % 1.0
    s = min(max(s * sat, 0.0), 1.0)
    v = v * val
    shifted = colorsys.hsv_to_rgb(h, s, v)
    out = tuple(max(fac * x + (1 - fac) * c, 0.0) for x, c in zip(shifted, colour))
    return out, r0 | r1 | r2 | r3 | r4

"""Shader mixes read as one Principled BSDF whose parameters are mixed.

Artists layer materials with Mix Shaders: two Principled BSDFs under a mask (rust over paint,
a metal inlay), a Diffuse and a Glossy BSDF mixed by a Fresnel (the classic plastic), a Glossy
BSDF alone (a metal), a Diffuse BSDF alone. The preview shades one Principled BSDF per texel,
so a mix is read as one whose parameters are the mix of its leaves':

* Each leaf is a Principled BSDF (its Base Color, Roughness, Metallic, Specular IOR Level and
  emission), a Diffuse BSDF (its Color; metallic 0, no specular layer), a Glossy BSDF (its
  Color and Roughness as a metal: a mirror tinted by the colour, as Cycles' Glossy is) or an
  Emission (black, and its light).
* A Mix Shader mixes its two sides' parameters by its Fac. Principled's Metallic blends its
  metal and dielectric lobes linearly, so a mix of a metal and a dielectric is exact; so is
  any mix under a mask of 0 or 1; a partial mix of two roughnesses is one lobe of the mean
  roughness (Cycles draws two).
* A Fac from a Fresnel node (or a Layer Weight's Fresnel) between a surface and a Glossy BSDF
  is the view-dependent reflection a Principled BSDF has of itself: the surface's parameters
  with the Glossy's roughness and a Specular IOR Level giving the Fresnel's reflectance at
  normal incidence (``(n − 1)² / (n + 1)²``, 0.08 at level 1).
* Where the Facs and the leaves' inputs are values, the mix is computed here; where any comes
  from nodes (a mask image, a noise), Cycles bakes two images over the mesh's UV map: the
  mixed Base Color (``BASE``), and the mixed Roughness, Metallic and Specular IOR Level as
  red, green and blue (``PARAMS``), built of Mix nodes in the bake's copy of the material
  (``route_to_emission``).

Not read this way (``read`` gives None, and the old reading stays): a mix inside a node group,
an Add Shader, a Transparent BSDF (the cut-out mix), any other shader.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .world_map import _follow, _NeedsBake

BASE, PARAMS = "Mixed Base Color", "Mixed Roughness, Metallic, Specular"
EXPRESSIONS = (BASE, PARAMS)
LEAVES = ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_GLOSSY", "BSDF_ANISOTROPIC", "EMISSION")
SPECULAR_AT_LEVEL_1 = 0.08  # a Principled BSDF's reflectance at normal incidence at level 1


@dataclass
class Leaf:
    node: object  # a shader node of LEAVES, or None (an unlinked shader input: black)


@dataclass
class Mix:
    node: object  # the Mix Shader
    first: Leaf | Mix
    second: Leaf | Mix
    fresnel: float | None = None  # a Fresnel Fac's index of refraction (the dielectric reading)


def read(tree) -> Leaf | Mix | None:
    """The tree of the active output's Surface when this module reads it: a Mix Shader of
    leaves (nested mixes too), or a Diffuse or Glossy BSDF alone (a Diffuse of one colour needs
    no bake); else None."""
    output = tree.get_output_node("ALL")
    surface = None if output is None else output.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return None
    try:
        node, _ = _follow(surface)
        if node is None or node.type not in ("MIX_SHADER", "BSDF_DIFFUSE", "BSDF_GLOSSY",
                                             "BSDF_ANISOTROPIC"):
            return None
        return _shader(node, 0)
    except _NeedsBake:
        return None


def _shader(node, depth: int):
    if node is None:
        return Leaf(None)
    if node.type in LEAVES:
        return Leaf(node)
    if node.type != "MIX_SHADER" or depth > 8:
        raise _NeedsBake(f"a '{node.name}' node")
    sides = []
    for socket in node.inputs[1:3]:
        source, _ = _follow(socket) if socket.is_linked else (None, None)
        sides.append(_shader(source, depth + 1))
    mix = Mix(node, *sides)
    fac = node.inputs[0]
    if fac.is_linked and isinstance(mix.second, Leaf) and mix.second.node is not None and \
            mix.second.node.type in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
        source, output = _follow(fac)
        if source is not None and source.type == "FRESNEL":
            mix.fresnel = float(source.inputs["IOR"].default_value)
        elif source is not None and source.type == "LAYER_WEIGHT" and output.identifier == "Fresnel":
            mix.fresnel = 1.0 / max(1.0 - float(source.inputs["Blend"].default_value), 1e-4)
    return mix


# ---------------------------------------------------------------------- the leaves' inputs

@dataclass
class _Glow:
    colour: object  # the Color / Emission Color socket
    strength: object  # the Strength socket


def _inputs(leaf: Leaf) -> dict:
    """{parameter: an input socket, or a value} of a leaf: base (RGB), roughness, metallic,
    specular, emission (RGB, × strength)."""
    node = leaf.node
    black = (0.0, 0.0, 0.0)
    if node is None:
        return {"base": black, "roughness": 1.0, "metallic": 0.0, "specular": 0.0, "emission": black}
    kind, inputs = node.type, node.inputs
    if kind == "BSDF_PRINCIPLED":
        return {"base": inputs["Base Color"], "roughness": inputs["Roughness"],
                "metallic": inputs["Metallic"], "specular": inputs["Specular IOR Level"],
                "emission": _Glow(inputs["Emission Color"], inputs["Emission Strength"])}
    if kind == "BSDF_DIFFUSE":
        return {"base": inputs["Color"], "roughness": 1.0, "metallic": 0.0, "specular": 0.0,
                "emission": black}
    if kind == "EMISSION":
        return {"base": black, "roughness": 1.0, "metallic": 0.0, "specular": 0.0,
                "emission": _Glow(inputs["Color"], inputs["Strength"])}
    return {"base": inputs["Color"], "roughness": inputs["Roughness"], "metallic": 1.0,
            "specular": 0.0, "emission": black}  # Glossy / Anisotropic: a tinted mirror


def _value(item) -> np.ndarray:
    if isinstance(item, _Glow):
        return _value(item.colour) * float(item.strength.default_value)
    if hasattr(item, "default_value"):
        value = item.default_value
        return np.array(value[:3] if hasattr(value, "__len__") else value, np.float64)
    return np.array(item, np.float64)


def _linked(item) -> bool:
    if isinstance(item, _Glow):
        return _linked(item.colour) or _linked(item.strength)
    return bool(getattr(item, "is_linked", False))


def _dielectric(mix: Mix) -> dict:
    """A Fresnel-mixed surface and Glossy read as one dielectric: which side gives which
    parameter (the surface's base, metallic and emission; the Glossy's roughness), and the
    specular level its index of refraction gives, × the Glossy colour's luminance."""
    f0 = ((mix.fresnel - 1.0) / (mix.fresnel + 1.0)) ** 2
    tint = _value(mix.second.node.inputs["Color"])
    level = f0 / SPECULAR_AT_LEVEL_1 * float(tint @ (0.2126, 0.7152, 0.0722))
    return {"base": mix.first, "roughness": mix.second, "metallic": mix.first,
            "emission": mix.first, "specular": level}


def needs_bake(shader, parameters) -> bool:
    """Does any of ``parameters`` of ``shader`` come from nodes (a linked Fac or input)?"""
    if isinstance(shader, Leaf):
        inputs = _inputs(shader)
        return any(_linked(inputs[p]) for p in parameters)
    if shader.fresnel is not None:
        sides = _dielectric(shader)
        return any(not isinstance(sides[p], float) and needs_bake(sides[p], (p,))
                   for p in parameters)
    return shader.node.inputs[0].is_linked or needs_bake(shader.first, parameters) or \
        needs_bake(shader.second, parameters)


def value(shader, parameter: str) -> np.ndarray:
    """The mixed ``parameter`` with every linked Fac and input at its own value."""
    if isinstance(shader, Leaf):
        return _value(_inputs(shader)[parameter])
    if shader.fresnel is not None:
        side = _dielectric(shader)[parameter]
        return np.array(side, np.float64) if isinstance(side, float) else value(side, parameter)
    fac = float(np.clip(shader.node.inputs[0].default_value, 0.0, 1.0))
    return (1.0 - fac) * value(shader.first, parameter) + fac * value(shader.second, parameter)


def leaves(shader) -> list:
    """The shader nodes at the leaves of ``shader`` (None for an unlinked side)."""
    if isinstance(shader, Leaf):
        return [shader.node]
    return leaves(shader.first) + leaves(shader.second)


def normal_socket(shader):
    """(the Normal input of a leaf, whether the leaves' Normals disagree): the one socket when
    every leaf whose Normal is linked takes it from the same node (a Normal Map feeding both
    sides of a layered material), None when none is linked or they come from several."""
    sockets = [node.inputs["Normal"] for node in leaves(shader)
               if node is not None and "Normal" in node.inputs and node.inputs["Normal"].is_linked]
    sources = set()
    for socket in sockets:
        try:
            source, output = _follow(socket)
        except _NeedsBake:
            return None, True
        sources.add((None if source is None else source.name, getattr(output, "identifier", None)))
    if len(sources) != 1:
        return None, len(sources) > 1
    return sockets[0], False


# ---------------------------------------------------------------------- bakes

def route_to_emission(tree, which: str) -> None:
    """Make a material copy's ``tree`` render an Emission of the mix's ``which`` (``BASE``:
    the mixed Base Color; ``PARAMS``: Roughness, Metallic and Specular IOR Level as RGB), built
    of Mix nodes from the copy's own sockets (the copy keeps the nodes' names)."""
    shader = read(tree)
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    if which == BASE:
        tree.links.new(_expression(tree, shader, "base"), emit.inputs["Color"])
    else:
        combine = tree.nodes.new("ShaderNodeCombineColor")
        for index, parameter in enumerate(("roughness", "metallic", "specular")):
            tree.links.new(_expression(tree, shader, parameter), combine.inputs[index])
        tree.links.new(combine.outputs[0], emit.inputs["Color"])
    output = tree.get_output_node("ALL")
    tree.links.new(emit.outputs[0], output.inputs["Surface"])


def _expression(tree, shader, parameter: str):
    """An output socket in ``tree`` giving ``parameter`` of ``shader`` per shading point."""
    colour = parameter == "base"
    if isinstance(shader, Leaf):
        item = _inputs(shader)[parameter]
        if _linked(item):
            return _source(item)
        return _constant(tree, _value(item), colour)
    if shader.fresnel is not None:
        side = _dielectric(shader)[parameter]
        if isinstance(side, float):
            return _constant(tree, np.array(side), colour)
        return _expression(tree, side, parameter)
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA" if colour else "FLOAT"
    fac = shader.node.inputs[0]
    factor = next(s for s in mix.inputs if s.identifier == "Factor_Float")
    if fac.is_linked:
        tree.links.new(_source(fac), factor)
    else:
        factor.default_value = float(fac.default_value)
    kind = "Color" if colour else "Float"
    first = next(s for s in mix.inputs if s.identifier == f"A_{kind}")
    second = next(s for s in mix.inputs if s.identifier == f"B_{kind}")
    tree.links.new(_expression(tree, shader.first, parameter), first)
    tree.links.new(_expression(tree, shader.second, parameter), second)
    return next(s for s in mix.outputs if s.identifier == f"Result_{kind}")


def _source(socket):
    """The output socket feeding ``socket`` (through reroutes)."""
    _, output = _follow(socket)
    return output


def _constant(tree, value: np.ndarray, colour: bool):
    if colour:
        node = tree.nodes.new("ShaderNodeRGB")
        node.outputs[0].default_value = (*np.broadcast_to(value, 3), 1.0)
    else:
        node = tree.nodes.new("ShaderNodeValue")
        node.outputs[0].default_value = float(value)
    return node.outputs[0]

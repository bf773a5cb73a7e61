"""What the preview cannot render yet, named per object (issue 22 point 4; main thread).

Cycles renders things the preview leaves out or approximates: refraction and transmission,
volumes, hair, displacement, subsurface scattering, the Principled BSDF's coat, sheen,
anisotropy, thin film, diffuse roughness and specular tint, shadow catchers. Rather than
dropping them silently, the snapshot says, once per object, what of it is left out: one report
line per object, ``Object 'Name': the preview leaves out A, B`` (``left_out_line``), which the
operators' reports and the sidebar panel show (``ui/panel.py`` lists them in their own box).

Read from the materials (``material_notes``: the active output's Volume and Displacement, the
Principled BSDF's inputs, the shader nodes feeding the surface) and from the object
(``object_notes``: shadow catchers, hair particle systems; ``type_note``: object types the
preview does not render at all — hair curves, point clouds, volume objects), from the lights
(``light_notes``: an area lamp's Spread, light nodes, light and
shadow linking, a light hidden from diffuse or glossy rays; ``Light 'Name': …`` lines) and from
the render (``render_notes``: the camera's depth of field, motion blur).
"""
from __future__ import annotations

from . import shader_mix
from .node_groups import GroupedSocket
from .world_map import _follow, _NeedsBake

MARK = ": the preview leaves out "
TYPE_NOTES = {"CURVES": "its hair curves (not rendered at all)",
              "POINTCLOUD": "its point cloud (not rendered at all)",
              "VOLUME": "its volume (not rendered at all)"}
# Principled BSDF inputs whose lobe the preview does not model (gi/principled.py): the
# weight or value socket, what to call it, the value at or below which the lobe is off (None:
# a colour, off when white).
PRINCIPLED_INPUTS = (
    ("Transmission Weight", "refraction (glass renders as a thin surface: the view and light "
                            "pass straight through, tinted)", 0.0),
    ("Subsurface Weight", "subsurface scattering (it renders as diffuse)", 0.0),
    ("Coat Weight", "the coat layer", 0.0),
    ("Sheen Weight", "sheen", 0.0),
    ("Anisotropic", "anisotropy", 0.0),
    ("Thin Film Thickness", "thin film", 0.0),
    ("Diffuse Roughness", "diffuse roughness (it renders Lambertian)", 0.0),
    ("Specular Tint", "the specular tint (it renders white)", None),
)
# Shader nodes feeding the surface that the preview does not model (other surfaces are read
# by their baked diffuse colour).
SHADER_NODES = {
    "BSDF_GLASS": "refraction (Glass BSDF)",
    "BSDF_REFRACTION": "refraction (Refraction BSDF)",
    "BSDF_TRANSLUCENT": "translucency",
    "SUBSURFACE_SCATTERING": "subsurface scattering",
    "BSDF_HAIR": "hair shading",
    "BSDF_HAIR_PRINCIPLED": "hair shading",
    "BSDF_SHEEN": "sheen",
    "BSDF_TOON": "toon shading",
}


def left_out_line(name: str, notes) -> str:
    """The report line naming object ``name`` and what of it is left out."""
    return f"Object '{name}'{MARK}{', '.join(dict.fromkeys(notes))}"


def is_left_out(message: str) -> bool:
    """Is a report message a ``left_out_line`` or a ``light_notes`` line?"""
    return message.startswith(("Object '", "Light '")) and MARK in message


def _upstream(socket, depth: int = 0, seen=None) -> list:
    """The nodes feeding ``socket`` (through links; a ``GroupedSocket``'s also into and out of
    node groups), nearest first."""
    seen = set() if seen is None else seen
    out = []
    if socket is None or depth > 32:
        return out
    for link in socket.links:
        if getattr(link, "is_muted", False):
            continue
        node = link.from_node
        key = (node.as_pointer(), tuple(g.as_pointer() for g in getattr(node, "stack", ())))
        if key in seen:
            continue
        seen.add(key)
        out.append(node)
        for inp in node.inputs:
            if inp.is_linked:
                out += _upstream(inp, depth + 1, seen)
    return out


def material_notes(material) -> list[str]:
    """What of ``material`` (a ``bpy.types.Material`` or None) the preview leaves out."""
    tree = getattr(material, "node_tree", None)
    if tree is None:
        return []
    notes = []
    output = tree.get_output_node("CYCLES") or tree.get_output_node("ALL")
    if output is None:
        return notes
    volume = output.inputs.get("Volume")
    if volume is not None and volume.is_linked:
        notes.append("its volume shader")
    surface = output.inputs.get("Surface")
    notes += _shader_mix_notes(surface)
    for node in _upstream(None if surface is None else GroupedSocket(surface, ())):
        if node.type == "BSDF_PRINCIPLED":
            for name, what, off in PRINCIPLED_INPUTS:
                socket = node.inputs.get(name)
                if socket is None:
                    continue
                if off is None:
                    on = min(socket.default_value[:3]) < 1.0
                else:
                    on = socket.default_value > off
                if socket.is_linked or on:
                    notes.append(what)
        elif node.type in SHADER_NODES:
            notes.append(SHADER_NODES[node.type])
    displacement = output.inputs.get("Displacement")
    if displacement is not None and displacement.is_linked and \
            getattr(material, "displacement_method", "BUMP") != "BUMP":
        notes.append("displacement")
    elif displacement is not None and displacement.is_linked:
        notes.append("bump from its displacement output")
    return list(dict.fromkeys(notes))


def _shader_mix_notes(surface) -> list[str]:
    """A surface the preview cannot read as one Principled BSDF: a Mix or Add Shader that
    ``shader_mix`` does not read (an Add Shader, a mix with another shader, a mix inside a
    group; the cut-out mix of a Transparent BSDF and a Principled BSDF is read too) is shaded
    with one Principled BSDF of it, or, with none, by its diffuse colour alone."""
    if surface is None or not surface.is_linked or shader_mix.read(surface.id_data) is not None:
        return []  # nothing, or a mix the preview reads as one mixed Principled BSDF
    try:
        top, _ = _follow(GroupedSocket(surface, ()))
    except _NeedsBake:
        return []
    if top is None:
        return []
    if top.type not in ("MIX_SHADER", "ADD_SHADER"):
        return []
    kinds = [n.type for n in _upstream(top.inputs[1] if top.type == "MIX_SHADER" else
                                       top.inputs[0])] + \
        [n.type for n in _upstream(top.inputs[2] if top.type == "MIX_SHADER" else
                                   top.inputs[1])]
    if top.type == "MIX_SHADER" and kinds[:1] == ["BSDF_TRANSPARENT"] and \
            "BSDF_PRINCIPLED" in kinds:
        return []  # a cut-out's mix (materials._transparent_mix)
    what = "Mix Shader" if top.type == "MIX_SHADER" else "Add Shader"
    if "BSDF_PRINCIPLED" in kinds:
        return [f"its {what} (the preview shades the surface with one Principled BSDF of it)"]
    return [f"its {what} (the preview shades the surface by its diffuse colour alone, "
            "without a glossy layer)"]


def object_notes(obj) -> list[str]:
    """What of ``obj`` itself (not its materials) the preview leaves out: a shadow catcher
    (rendered as an ordinary surface), hair particle systems Cycles renders (their modifier
    enabled for renders, the system rendered as paths)."""
    notes = ["its shadow catcher (it renders as an ordinary surface)"] \
        if getattr(obj, "is_shadow_catcher", False) else []
    for modifier in getattr(obj, "modifiers", ()):
        if modifier.type != "PARTICLE_SYSTEM" or not modifier.show_render:
            continue
        settings = modifier.particle_system.settings
        if settings.type == "HAIR" and settings.render_type == "PATH":
            notes.append("its hair particles")
    return notes


def render_notes(scene) -> list[str]:
    """What of the render's own settings the preview leaves out: the scene camera's depth of
    field (it renders everything in focus) and motion blur (every object at its frame's
    place), each a report line naming where it is set."""
    notes = []
    camera = scene.camera
    dof = getattr(getattr(camera, "data", None), "dof", None)
    if dof is not None and dof.use_dof:
        notes.append(f"Camera '{camera.name}'{MARK}depth of field (it renders everything in "
                     "focus)")
    if scene.render.use_motion_blur:
        notes.append(f"Render Properties{MARK}motion blur (every object renders at its "
                     "place at the frame)")
    return notes


def light_notes(obj) -> str | None:
    """The report line naming what of light object ``obj`` the preview leaves out (it lights as
    Cycles' defaults have it), else None: an area lamp's Spread under 180° (Cycles narrows its
    light to a soft box's cone, the same power brighter beneath it), a node tree, light or
    shadow linking, the light hidden from diffuse or glossy rays."""
    import math

    light = obj.data
    notes = []
    spread = getattr(light, "spread", math.pi)
    if light.type == "AREA" and spread < math.pi - 1e-3:
        notes.append(f"its Spread of {math.degrees(spread):.0f}° (it lights as a spread of 180°)")
    if getattr(light, "use_nodes", False) and getattr(light, "node_tree", None) is not None:
        notes.append("its light nodes (it emits its Color × Power)")
    linking = getattr(obj, "light_linking", None)
    if linking is not None and linking.receiver_collection is not None:
        notes.append("its light linking (it lights every object)")
    if linking is not None and linking.blocker_collection is not None:
        notes.append("its shadow linking (every object shadows it)")
    hidden = [kind for kind, seen in (("diffuse", getattr(obj, "visible_diffuse", True)),
                                      ("glossy", getattr(obj, "visible_glossy", True))) if not seen]
    if hidden:
        notes.append(f"its hiding from {' and '.join(hidden)} rays (it lights both)")
    return f"Light '{obj.name}'{MARK}{', '.join(notes)}" if notes else None


def type_note(obj) -> str | None:
    """The note for an object type the preview does not render at all, else None."""
    return TYPE_NOTES.get(obj.type)


def notes_of(obj, material_names, notes_by_material: dict) -> list[str]:
    """What of an object the preview leaves out: ``object_notes`` of ``obj`` (None: none) and
    the notes of each of its materials (``material_names``, by ``notes_by_material``), each
    material's named after them."""
    notes = [] if obj is None else object_notes(obj)
    for name in dict.fromkeys(material_names):
        found = notes_by_material.get(name)
        if found:
            notes.append(f"{', '.join(found)} [material '{name}']")
    return notes

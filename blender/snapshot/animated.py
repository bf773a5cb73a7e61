"""Animated node values of materials and worlds at the frame a depsgraph was evaluated at.

A render's depsgraph (F12, an animation render) evaluates animation on its own copies of the
datablocks; the user's datablocks keep the values of the frame the UI shows. Reading a material
or a world from the user's datablock therefore froze its keyframed values (an emission that
blinks, a colour that fades, a sun that sets) at that frame in every frame of an animation
render. So a material or world whose node tree is animated (keyframes, drivers, NLA strips) is
read from the depsgraph's evaluated copy (``reads_evaluated``), and a Cycles bake of it, which
renders a copy of the user's datablock (a copy of an evaluated one would point at the
depsgraph's own images), takes the evaluated values of the animated paths (``frame_values``,
``apply``) after its own animation is cleared. Images are always read through the user's
datablocks (``original``): an evaluated image holds no pixels.
"""
from __future__ import annotations

__all__ = ["animated_paths", "apply", "frame_values", "original", "reads_evaluated"]


def original(id_data):
    """The user's datablock of ``id_data`` (itself when it is one; None stays None)."""
    if id_data is None:
        return None
    return getattr(id_data, "original", None) or id_data


def animated_paths(id_data) -> tuple[str, ...]:
    """The RNA paths (relative to ``id_data``) its animation data drives: the F-Curves of its
    action's slot (layered actions, Blender 4.4+; an action's own F-Curves before), of its NLA
    strips' actions, and its drivers."""
    anim = getattr(id_data, "animation_data", None)
    if anim is None:
        return ()
    paths = [driver.data_path for driver in anim.drivers]
    actions = [(anim.action, getattr(anim, "action_slot", None))]
    for track in anim.nla_tracks:
        if not track.mute:
            actions += [(strip.action, getattr(strip, "action_slot", None))
                        for strip in track.strips if strip.action is not None]
    for action, slot in actions:
        if action is None:
            continue
        if hasattr(action, "layers") and len(action.layers):
            for layer in action.layers:
                for strip in layer.strips:
                    for bag in getattr(strip, "channelbags", ()):
                        if slot is None or bag.slot == slot:
                            paths += [curve.data_path for curve in bag.fcurves]
        elif hasattr(action, "fcurves"):
            paths += [curve.data_path for curve in action.fcurves]
    return tuple(dict.fromkeys(p for p in paths if p))


def reads_evaluated(id_data) -> bool:
    """Is ``id_data`` (a material or world, evaluated or not) to be read from its evaluated
    copy: its node tree or itself is animated?"""
    source = original(id_data)
    return bool(animated_paths(getattr(source, "node_tree", None)) or animated_paths(source))


def frame_values(evaluated) -> list[tuple[str, str, object]]:
    """(``"tree"`` or ``"id"``, path, value) of every animated path of ``evaluated`` 's user
    datablock (its node tree's and its own), read on ``evaluated`` — its values at the frame
    its depsgraph was evaluated at; empty when nothing is animated or ``evaluated`` is the
    user's own."""
    source = original(evaluated)
    if evaluated is None or source is evaluated:
        return []
    values = []
    for owner, target in (("tree", "node_tree"), ("id", None)):
        here = source if target is None else getattr(source, target, None)
        there = evaluated if target is None else getattr(evaluated, target, None)
        if here is None or there is None:
            continue
        for path in animated_paths(here):
            try:
                value = there.path_resolve(path)
            except ValueError:  # a path that no longer resolves (a deleted node's curve)
                continue
            if hasattr(value, "__len__") and not isinstance(value, str):
                value = tuple(value)
            values.append((owner, path, value))
    return values


def apply(copy, values) -> None:
    """Give ``copy`` (a copy of the user's datablock, about to be baked) the ``values`` of
    ``frame_values``, its own animation cleared first (else its render would evaluate it)."""
    tree = getattr(copy, "node_tree", None)
    if tree is not None and tree.animation_data is not None:
        tree.animation_data_clear()
    if copy.animation_data is not None:
        copy.animation_data_clear()
    for owner, path, value in values:
        target = tree if owner == "tree" else copy
        if target is None:
            continue
        holder, _, name = path.rpartition(".")
        try:
            item = target.path_resolve(holder) if holder else target
            if name.endswith("]"):  # an element of an array property: name[k]
                name, _, index = name[:-1].partition("[")
                getattr(item, name)[int(index)] = value
            else:
                setattr(item, name, value)
        except (ValueError, AttributeError, TypeError, IndexError):
            continue  # a path the copy does not have: its value stays

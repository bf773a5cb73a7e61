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


def _groups(tree, depth: int = 0):
    """The node groups ``tree`` uses, nested ones too (each once)."""
    seen = {}
    for node in tree.nodes if tree is not None and depth <= 8 else ():
        group = getattr(node, "node_tree", None) if node.type == "GROUP" else None
        if group is not None and group.name_full not in seen:
            seen[group.name_full] = group
            for inner in _groups(group, depth + 1):
                seen.setdefault(inner.name_full, inner)
    return list(seen.values())


def reads_evaluated(id_data) -> bool:
    """Is ``id_data`` (a material or world, evaluated or not) to be read from its evaluated
    copy: its node tree, a node group it uses, or itself is animated?"""
    source = original(id_data)
    tree = getattr(source, "node_tree", None)
    return bool(animated_paths(tree) or animated_paths(source) or
                any(animated_paths(group) for group in _groups(tree)))


def frame_values(evaluated) -> list[tuple[str, str, object]]:
    """(``"tree"``, ``"id"`` or ``"group:<name>"``, path, value) of every animated path of
    ``evaluated`` 's user datablock (its node tree's, its node groups', its own), read on
    ``evaluated``: its values at the frame its depsgraph was evaluated at; empty when nothing
    is animated or ``evaluated`` is the user's own."""
    source = original(evaluated)
    if evaluated is None or source is evaluated:
        return []
    values = []
    pairs = [("tree", getattr(source, "node_tree", None), getattr(evaluated, "node_tree", None)),
             ("id", source, evaluated)]
    # node groups: the evaluated tree's groups are the depsgraph's copies of the user's
    pairs += [(f"group:{original(group).name_full}", original(group), group)
              for group in _groups(getattr(evaluated, "node_tree", None))]
    for owner, here, there in pairs:
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


def apply(copy, values) -> list:
    """Give ``copy`` (a copy of the user's datablock, about to be baked) the ``values`` of
    ``frame_values``, its own animation cleared first (else its render would evaluate it). An
    animated node group gets a copy of its own with its values, put in place of the user's in
    ``copy`` 's tree (and in the other copies): the copies made, for the caller to remove."""
    import bpy

    tree = getattr(copy, "node_tree", None)
    if tree is not None and tree.animation_data is not None:
        tree.animation_data_clear()
    if copy.animation_data is not None:
        copy.animation_data_clear()
    groups: dict = {}  # the user's group → its copy
    for owner, _path, _value in values:
        name = owner[len("group:"):] if owner.startswith("group:") else None
        group = None if name is None else bpy.data.node_groups.get(name)
        if group is not None and group not in groups:
            groups[group] = group.copy()
            if groups[group].animation_data is not None:
                groups[group].animation_data_clear()
    for holder in ([tree] if tree is not None else []) + list(groups.values()):
        for node in holder.nodes:
            if node.type == "GROUP" and node.node_tree in groups:
                node.node_tree = groups[node.node_tree]
    by_name = {f"group:{g.name_full}": c for g, c in groups.items()}
    for owner, path, value in values:
        target = tree if owner == "tree" else by_name.get(owner) if owner.startswith("group:") \
            else copy
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
    return list(groups.values())

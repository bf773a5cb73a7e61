"""Materials wrapped in node groups, read as if flat (main thread only).

Asset libraries ship materials whose Principled BSDF sits inside a node group (often nested),
its inputs wired to the group's inputs or to textures inside the group. ``surface_node``
follows the active output's Surface through reroutes and into Group nodes to the shader that
renders; a node found inside a group comes as a ``GroupedNode``. Its input sockets are
``GroupedSocket``s, which read as the flat tree would: a link from the group's Group Input
continues outside at the Group node's own input (its value, or what feeds it there), a link
from a Group node continues inside at its Group Output's socket, reroutes are passed. Every
other attribute is the node's or socket's own, so ``materials.py`` reads a grouped material
with the code it reads a flat one with.

A bake of a grouped material's socket (``route_to_emission``) routes an Emission shader to the
output from where the socket's value is: in the material's own tree, or, inside a group, in
copies of the groups on the way (the user's groups stay as they are; the caller removes the
copies).
"""
from __future__ import annotations

from .world_map import _follow, _NeedsBake

__all__ = ["GroupedNode", "GroupedSocket", "route_to_emission", "surface_node"]

MAX_STEPS = 256  # links followed for one socket (a cycle through groups cannot hang the read)


def _group_output(tree):
    """The active Group Output node of a group's tree, else the first, else None."""
    outputs = [n for n in tree.nodes if n.type == "GROUP_OUTPUT"]
    return next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)


def _by_identifier(sockets, identifier):
    return next((s for s in sockets if s.identifier == identifier), None)


def _resolve(socket, stack, enter: bool = True):
    """(socket, stack) an input socket reads from: reroutes passed, a Group Input left for the
    enclosing Group node's input, a Group node entered at its Group Output (``enter``). The
    socket returned is unlinked (its value counts) or linked from any other node."""
    for _ in range(MAX_STEPS):
        if not socket.is_linked:
            break
        link = socket.links[0]
        if link.is_muted:
            break
        node = link.from_node
        if node.type == "REROUTE" and not node.mute:
            socket = node.inputs[0]
        elif node.type == "GROUP_INPUT" and stack:
            outer = _by_identifier(stack[-1].inputs, link.from_socket.identifier)
            if outer is None:
                break
            socket, stack = outer, stack[:-1]
        elif enter and node.type == "GROUP" and not node.mute and node.node_tree is not None:
            output = _group_output(node.node_tree)
            inner = None if output is None else \
                _by_identifier(output.inputs, link.from_socket.identifier)
            if inner is None:
                break
            socket, stack = inner, (*stack, node)
        else:
            break
    return socket, stack


class _Sockets:
    """A node's inputs or outputs as ``GroupedSocket``s (by name, index, iteration)."""

    def __init__(self, sockets, stack):
        self._sockets, self._stack = sockets, stack

    def __getitem__(self, key):
        return GroupedSocket(self._sockets[key], self._stack)

    def get(self, key, default=None):
        socket = self._sockets.get(key)
        return default if socket is None else GroupedSocket(socket, self._stack)

    def __iter__(self):
        return (GroupedSocket(s, self._stack) for s in self._sockets)

    def __contains__(self, key):
        return key in self._sockets

    def __len__(self):
        return len(self._sockets)


class GroupedNode:
    """A node inside (nested) groups: ``stack`` the Group nodes it is inside, outermost first;
    ``node`` the node itself."""

    def __init__(self, node, stack):
        self.node, self.stack = node, tuple(stack)

    @property
    def inputs(self):
        return _Sockets(self.node.inputs, self.stack)

    @property
    def outputs(self):
        return _Sockets(self.node.outputs, self.stack)

    def __eq__(self, other):
        if isinstance(other, GroupedNode):
            return self.node == other.node and self.stack == other.stack
        return not self.stack and self.node == other

    def __hash__(self):
        return hash((self.node.as_pointer(), tuple(g.as_pointer() for g in self.stack)))

    def __getattr__(self, name):
        return getattr(self.node, name)


class _Link:
    def __init__(self, link, stack):
        self._link, self._stack = link, stack

    @property
    def from_node(self):
        return GroupedNode(self._link.from_node, self._stack)

    @property
    def from_socket(self):
        return GroupedSocket(self._link.from_socket, self._stack)

    def __getattr__(self, name):
        return getattr(self._link, name)


class GroupedSocket:
    """A socket of a ``GroupedNode``: its link and value are the ones it reads through the
    groups (``_resolve``); ``node`` is its own node; the rest is the socket's."""

    def __init__(self, socket, stack):
        self.socket, self.stack = socket, tuple(stack)
        self._resolved = None

    def _source(self):
        if self._resolved is None:
            self._resolved = _resolve(self.socket, self.stack) if not self.socket.is_output \
                else (self.socket, self.stack)
        return self._resolved

    @property
    def is_linked(self):
        return self._source()[0].is_linked

    @property
    def links(self):
        socket, stack = self._source()
        return [_Link(link, stack) for link in socket.links]

    @property
    def default_value(self):
        return self._source()[0].default_value

    @property
    def node(self):
        return GroupedNode(self.socket.node, self.stack)

    def __getattr__(self, name):
        return getattr(self.socket, name)


def surface_node(tree, node_type: str):
    """The node of ``node_type`` the active output's Surface renders — followed through
    reroutes and Group nodes (a ``GroupedNode`` when inside a group) — else the tree's first
    node of that type, else None."""
    output = tree.get_output_node("ALL")
    surface = None if output is None else output.inputs.get("Surface")
    if surface is not None and surface.is_linked:
        try:
            node, _ = _follow(GroupedSocket(surface, ()))
        except _NeedsBake:
            node = None
        if node is not None and node.type == node_type:
            return node if node.stack else node.node
    return next((n for n in tree.nodes if n.type == node_type), None)


def route_to_emission(tree, socket_name: str, new_groups: list) -> None:
    """Make a material copy's ``tree`` render an Emission shader of what feeds its rendered
    Principled BSDF's ``socket_name`` (its value when unlinked). Where that value is inside
    groups, the groups on the way are copied (appended to ``new_groups``, for the caller to
    remove) and the Emission goes out through the copies' Group Outputs."""
    principled = surface_node(tree, "BSDF_PRINCIPLED")
    path = _surface_path(tree)  # [(group node, its output identifier)], outermost first
    target = principled.inputs[socket_name]
    raw = target.socket if isinstance(target, GroupedSocket) else target
    stack = target.stack if isinstance(target, GroupedSocket) else ()
    source, stack = _resolve(raw, stack, enter=False)  # stays on the surface's path
    depth = len(stack)
    level = tree
    for group, _ in path[:depth]:  # copy each group on the way, and go into the copy
        here = level.nodes[group.name]  # the path's node, in the tree (or copy) it lies in
        copy = here.node_tree.copy()
        new_groups.append(copy)
        here.node_tree = copy
        level = copy
    emit = level.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    if source.is_linked:
        link = source.links[0]
        origin = level.nodes[link.from_node.name] if depth else link.from_node
        level.links.new(_by_identifier(origin.outputs, link.from_socket.identifier),
                        emit.inputs["Color"])
    else:
        emit.inputs["Color"].default_value = tuple(source.default_value)
    if depth:
        output = _group_output(level)
        level.links.new(emit.outputs["Emission"],
                        _by_identifier(output.inputs, path[depth - 1][1]))
        return
    output = tree.get_output_node("CYCLES")
    if output is None:
        output = tree.nodes.new("ShaderNodeOutputMaterial")
    for node in tree.nodes:  # the only active output
        if node.type == "OUTPUT_MATERIAL":
            node.is_active_output = node == output
    tree.links.new(emit.outputs["Emission"], output.inputs["Surface"])


def _surface_path(tree) -> list:
    """The Group nodes (with the output identifier the shader leaves each by) the active
    output's Surface passes through to the shader it renders, outermost first."""
    output = tree.get_output_node("ALL")
    surface = None if output is None else output.inputs.get("Surface")
    path, socket = [], surface
    for _ in range(MAX_STEPS):
        if socket is None or not socket.is_linked:
            break
        link = socket.links[0]
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
        elif node.type == "GROUP" and node.node_tree is not None:
            identifier = link.from_socket.identifier
            path.append((node, identifier))
            group_out = _group_output(node.node_tree)
            socket = None if group_out is None else _by_identifier(group_out.inputs, identifier)
        else:
            break
    return path

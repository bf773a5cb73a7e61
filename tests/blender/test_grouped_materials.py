"""Materials wrapped in node groups (blender/snapshot/node_groups.py), as asset libraries ship
them: the Principled BSDF inside a group (nested too), its inputs from the group's inputs or
from nodes inside it, read as the flat material would be, a bake routed through copies of the
groups, and the user's groups left as they were."""
from __future__ import annotations

import bpy
import gi_scenes
import numpy as np
from cycles_reference import render_cycles_passes

WIDTH, HEIGHT = 80, 60


def _group(name, exposed=("Base Color", "Roughness"), inner=None):
    """A shader group: a Principled BSDF (Metallic 1) to its Shader output, the inputs in
    ``exposed`` wired to the group's inputs; ``inner`` (tree, principled) → None adds nodes
    inside it."""
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    kinds = {"Base Color": "NodeSocketColor", "Roughness": "NodeSocketFloat"}
    for socket in exposed:
        group.interface.new_socket(socket, in_out="INPUT", socket_type=kinds[socket])
    inputs, outputs = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    principled = group.nodes.new("ShaderNodeBsdfPrincipled")
    principled.inputs["Metallic"].default_value = 1.0
    principled.inputs["Base Color"].default_value = (0.2, 0.9, 0.2, 1.0)
    principled.inputs["Roughness"].default_value = 0.6
    for socket in exposed:
        group.links.new(inputs.outputs[socket], principled.inputs[socket])
    group.links.new(principled.outputs[0], outputs.inputs["Shader"])
    if inner is not None:
        inner(group, principled)
    return group


def _grouped_material(name, group, values=None, wrap=0):
    """A material whose Surface is ``group``'s Shader, its inputs set to ``values``; ``wrap``
    more groups around it, each passing its inputs and Shader through."""
    for level in range(wrap):
        outer = bpy.data.node_groups.new(f"{name} wrap {level}", "ShaderNodeTree")
        outer.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
        node = outer.nodes.new("ShaderNodeGroup")
        node.node_tree = group
        inputs = outer.nodes.new("NodeGroupInput")
        for socket in node.inputs:
            outer.interface.new_socket(socket.name, in_out="INPUT",
                                       socket_type=socket.bl_idname)
            outer.links.new(inputs.outputs[socket.name], node.inputs[socket.name])
        outer.links.new(node.outputs["Shader"],
                        outer.nodes.new("NodeGroupOutput").inputs["Shader"])
        group = outer
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5.0 creates materials without nodes
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.remove(next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"))
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    for socket, value in (values or {}).items():
        node.inputs[socket].default_value = value
    tree.links.new(node.outputs["Shader"], tree.nodes["Material Output"].inputs["Surface"])
    return material


def _checker_inside(group, principled):
    checker = group.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.9, 0.6, 0.1, 1.0)
    checker.inputs["Color2"].default_value = (0.1, 0.2, 0.7, 1.0)
    group.links.new(checker.outputs["Color"], principled.inputs["Base Color"])


def _tree_state():
    """Every node group's nodes and links, and the materials' (what a read must not change)."""
    trees = [*bpy.data.node_groups, *(m.node_tree for m in bpy.data.materials if m.node_tree)]
    return sorted((t.name_full, len(t.nodes), len(t.links)) for t in trees), \
        len(bpy.data.node_groups), len(bpy.data.materials), len(bpy.data.images)


def test_a_grouped_principled_reads_as_the_flat_one(voxgi):
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = bpy.context.scene
    gold = _grouped_material("Gold", _group("Metal"), {"Base Color": (1.0, 0.78, 0.34, 1.0),
                                                       "Roughness": 0.25})
    nested = _grouped_material("Copper", _group("Metal 2"), {"Base Color": (0.95, 0.64, 0.54, 1),
                                                            "Roughness": 0.35}, wrap=2)
    fixed = _grouped_material("Green", _group("Fixed", exposed=()))
    coated = _grouped_material("Coated", _group("Coated Group", inner=lambda group, principled:
                                                principled.inputs["Coat Weight"].__setattr__(
                                                    "default_value", 1.0)))
    quad = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    for k, material in enumerate((gold, nested, fixed, coated)):
        gi_scenes._mesh(scene, f"Quad {k}", quad, [(0, 1, 2, 3)], (material,)).location.x = 3 * k
    before = _tree_state()
    snapshot = take_snapshot(scene)
    assert _tree_state() == before
    assert not [w for w in snapshot.warnings if "Gold" in w or "Copper" in w or "Green" in w]
    # what the preview leaves out is read inside the group too
    assert [w for w in snapshot.warnings if "Quad 3" in w and "coat" in w], snapshot.warnings
    read = {m.name: m for m in snapshot.materials}
    for name, colour, rough in (("Gold", (1.0, 0.78, 0.34), 0.25),
                                ("Copper", (0.95, 0.64, 0.54), 0.35),
                                ("Green", (0.2, 0.9, 0.2), 0.6)):
        np.testing.assert_allclose(read[name].base_color, colour, atol=1e-6)
        assert read[name].metallic == 1.0 and abs(read[name].roughness - rough) < 1e-6


def test_a_texture_inside_a_group_is_baked_through_copies_of_the_groups(voxgi):
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = bpy.context.scene
    material = _grouped_material("Checker Metal", _group("Checker Group", exposed=("Roughness",),
                                                         inner=_checker_inside), wrap=1)
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    plane.data.materials.append(material)
    before = _tree_state()
    snapshot = take_snapshot(scene)
    assert _tree_state() == before  # the bake's copies of the groups are gone
    data = next(m for m in snapshot.materials if m.name == "Checker Metal")
    assert data.base_color_texture >= 0
    pixels = snapshot.textures[data.base_color_texture].pixels[..., :3].reshape(-1, 3)
    # the checker's two colours, half each over the plane's UV square
    np.testing.assert_allclose(pixels.mean(axis=0), [0.5, 0.4, 0.4], atol=0.02)
    assert (np.abs(pixels - [0.9, 0.6, 0.1]).max(-1) < 0.02).mean() > 0.4
    assert (np.abs(pixels - [0.1, 0.2, 0.7]).max(-1) < 0.02).mean() > 0.4


def test_grouped_metals_reflect_as_in_cycles(voxgi, tmp_path):
    """Three spheres of grouped metals (one nested twice) in a lit room: the preview's Glossy
    Color is Cycles' (a grouped metal read as a diffuse bake was black, with no glossy)."""
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    scene = bpy.context.scene
    grey = gi_scenes._material("Wall", (0.7, 0.7, 0.7))
    for name, vertices in (("Floor", [(-4, -3, 0), (4, -3, 0), (4, 4, 0), (-4, 4, 0)]),
                           ("Back", [(-4, 4, 0), (4, 4, 0), (4, 4, 4), (-4, 4, 4)])):
        gi_scenes._mesh(scene, name, vertices, [(0, 1, 2, 3)], (grey,))
    metals = (((1.0, 0.78, 0.34), 0.3, 0), ((0.95, 0.64, 0.54), 0.2, 2), ((0.9, 0.9, 0.9), 0.4, 1))
    for k, (colour, rough, wrap) in enumerate(metals):
        material = _grouped_material(f"Metal {k}", _group(f"Metal Group {k}"),
                                     {"Base Color": (*colour, 1.0), "Roughness": rough}, wrap)
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(2.0 * k - 2.0, 0.5, 0.8))
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(material)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "AREA"))
    lamp.data.energy, lamp.data.size, lamp.location = 500.0, 1.5, (0.0, -1.0, 3.5)
    scene.collection.objects.link(lamp)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location, camera.rotation_euler = (0.0, -6.0, 1.5), (1.45, 0.0, 0.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    world = bpy.data.worlds.new("Sky")
    world.color = (0.3, 0.3, 0.35)
    scene.world = world
    scene.cycles.filter_width = 0.01
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=WIDTH,
                                        resolution_y=HEIGHT) == {"FINISHED"}
    ours = read_exr_passes(str(tmp_path / "p.exr"))
    cycles = render_cycles_passes(scene, WIDTH, HEIGHT, 4, filter_width=0.01)
    spheres = np.asarray(cycles["Glossy Color"]).max(-1) > 0.5  # the metals' pixels
    assert spheres.sum() > 300
    glossy = np.asarray(ours["Glossy Color"], np.float64)[spheres]
    np.testing.assert_allclose(glossy.mean(axis=0),
                               np.asarray(cycles["Glossy Color"], np.float64)[spheres].mean(axis=0),
                               atol=0.03)
    assert np.asarray(ours["Diffuse Color"], np.float64)[spheres].max() < 0.05  # no diffuse

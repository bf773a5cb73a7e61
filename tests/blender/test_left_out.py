"""Say what is left out (issue 22 point 4): what the preview cannot render yet — refraction /
transmission, volumes, hair curves … — is named per object, once, in the operators' reports
and in the sidebar panel (blender/snapshot/left_out.py), not dropped silently."""
from __future__ import annotations

import math

import bpy
import gi_scenes


class _Layout:
    """Records the labels a panel draws; every container call returns itself."""

    def __init__(self):
        self.labels = []

    def box(self, **_kwargs):
        return self

    row = column = box

    def label(self, text="", icon="NONE"):
        self.labels.append(text)

    def operator(self, *_args, **_kwargs):
        pass

    def prop(self, *_args, **_kwargs):
        pass


def _node_material(name):
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    return material


def build(scene):
    """A floor with a glass pane (Principled Transmission), a glass sphere (Glass BSDF), a
    cube of smoke (a Principled Volume, no surface), a hair curves object, a plain box; a sun
    and a camera."""
    white = gi_scenes._material("White", (0.7, 0.7, 0.7))
    gi_scenes._mesh(scene, "Floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._block(scene, "Plain Box", (0.5, 0.5, 0.5), (1.5, 1.0, 0.0), 0.0, white)
    glass = gi_scenes._material("Window Glass", (0.9, 0.9, 0.9))
    glass.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    gi_scenes._mesh(scene, "Glass Pane", [(-1, 0, 0), (1, 0, 0), (1, 0, 1.5), (-1, 0, 1.5)],
                    [(0, 1, 2, 3)], (glass,))
    crystal = _node_material("Crystal")
    tree = crystal.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    glass_bsdf = tree.nodes.new("ShaderNodeBsdfGlass")
    tree.links.new(glass_bsdf.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=0.4,
                                         location=(-1.5, 1.0, 0.4))
    sphere = bpy.context.active_object
    sphere.name = "Crystal Ball"
    sphere.data.materials.append(crystal)
    smoke = _node_material("Smoke")
    tree = smoke.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    volume = tree.nodes.new("ShaderNodeVolumePrincipled")
    tree.links.new(volume.outputs["Volume"], tree.nodes["Material Output"].inputs["Volume"])
    gi_scenes._block(scene, "Smoke Cube", (0.8, 0.8, 0.8), (0.0, 1.5, 0.0), 0.0, smoke)
    hair = bpy.data.objects.new("Fur", bpy.data.hair_curves.new("Fur"))
    scene.collection.objects.link(hair)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.3, 0.8, -0.45), energy=2.0,
                     angle=math.radians(1.0))
    gi_scenes._camera(scene, "Camera", (0.0, -6.0, 2.5), (0.0, 0.5, 0.5), lens=30.0)
    gi_scenes._finish(scene, {})


EXPECTED = {"Glass Pane": "refraction (glass renders as a thin surface", "Crystal Ball": "refraction (Glass BSDF)",
            "Smoke Cube": "its volume shader", "Fur": "hair curves"}


def _named(report):
    """{object name: [its left-out lines]} of a report's WARNING lines."""
    out = {}
    for level, line in report:
        for name in (*EXPECTED, "Floor", "Plain Box"):
            if level == "WARNING" and line.startswith(f"Object '{name}'"):
                out.setdefault(name, []).append(line)
    return out


def test_the_report_and_the_panel_name_each_object_and_what_is_left_out(voxgi, tmp_path):
    from voxgi.blender.session import scene_session

    scene = bpy.context.scene
    build(scene)
    for run in range(2):  # a second render says it again, once
        assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / f"p{run}.exr"),
                                            resolution_x=32, resolution_y=24) == {"FINISHED"}
        report = scene_session(scene.name_full).last_report
        named = _named(report)
        assert set(named) == set(EXPECTED), report  # the floor and the plain box: nothing
        for name, what in EXPECTED.items():
            assert len(named[name]) == 1, (name, named[name])
            assert "the preview leaves out" in named[name][0] and what in named[name][0], named[name]
        assert "'Window Glass'" in named["Glass Pane"][0]  # the material is named too
        assert "'Smoke'" in named["Smoke Cube"][0]
    layout = _Layout()
    bpy.types.VOXGI_PT_main.draw(type("PanelStub", (), {"layout": layout})(), bpy.context)
    assert "Not rendered by the preview yet" in layout.labels
    for name, what in EXPECTED.items():
        at = layout.labels.index(f"Object '{name}':")
        assert what in layout.labels[at + 1], layout.labels
    assert sum(text.startswith("Object 'Glass Pane'") for text in layout.labels) == 1


def test_voxelize_and_update_say_it_too(voxgi):
    from voxgi.blender.session import scene_session

    scene = bpy.context.scene
    build(scene)
    for operator in (bpy.ops.voxgi.voxelize, bpy.ops.voxgi.update):
        assert operator() == {"FINISHED"}
        named = _named(scene_session(scene.name_full).last_report)
        assert set(named) == set(EXPECTED), operator
        assert all(len(lines) == 1 for lines in named.values())


def test_hair_particles_displacement_and_shadow_catchers_are_named(voxgi):
    """A mesh with a hair particle system rendered as paths, a material whose output has a
    Displacement linked (as Bump, Cycles' default) and a shadow catcher are named too."""
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = bpy.context.scene
    build(scene)
    box = bpy.data.objects["Plain Box"]
    box.modifiers.new("Hair", "PARTICLE_SYSTEM")
    box.particle_systems[0].settings.type = "HAIR"
    tree = bpy.data.materials["White"].node_tree
    noise = tree.nodes.new("ShaderNodeTexNoise")
    displace = tree.nodes.new("ShaderNodeDisplacement")
    tree.links.new(noise.outputs["Fac"], displace.inputs["Height"])
    tree.links.new(displace.outputs["Displacement"], tree.nodes["Material Output"].inputs["Displacement"])
    bpy.data.objects["Floor"].is_shadow_catcher = True
    warnings = take_snapshot(scene).warnings
    box_lines = [w for w in warnings if w.startswith("Object 'Plain Box'")]
    assert len(box_lines) == 1 and "hair particles" in box_lines[0], warnings
    assert "displacement" in box_lines[0] and "'White'" in box_lines[0]
    floor = [w for w in warnings if w.startswith("Object 'Floor'")]
    assert len(floor) == 1 and "displacement" in floor[0] and "shadow catcher" in floor[0]


def test_depth_of_field_and_motion_blur_are_named(voxgi):
    """The camera's depth of field and the render's motion blur, which Cycles renders and the
    preview does not, are said once each, naming where they are set; off, nothing is said."""
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = bpy.context.scene
    build(scene)
    assert not any("depth of field" in w or "motion blur" in w
                   for w in take_snapshot(scene).warnings)
    scene.camera.data.dof.use_dof = True
    scene.render.use_motion_blur = True
    warnings = take_snapshot(scene).warnings
    dof = [w for w in warnings if "depth of field" in w]
    blur = [w for w in warnings if "motion blur" in w]
    assert dof == [f"Camera '{scene.camera.name}': the preview leaves out depth of field (it "
                   "renders everything in focus)"], warnings
    assert len(blur) == 1 and blur[0].startswith("Render Properties: the preview leaves out"), warnings


def test_light_settings_the_preview_leaves_out_are_named(voxgi, tmp_path):
    """A soft box (an area lamp of Spread 45°: Cycles narrows its light to that cone, the image
    half again as bright under it), a light linked to one collection and a light hidden from
    glossy rays: each light is named once in the report and the panel with what of it the
    preview leaves out; a plain light and a fill light that casts no shadow (rendered so:
    test_direct_vs_cycles.py) are not."""
    from voxgi.blender.session import scene_session

    scene = bpy.context.scene
    build(scene)
    lamps = {}
    for name, kind in (("Soft Box", "AREA"), ("Fill", "POINT"), ("Linked", "SPOT"),
                       ("No Glint", "POINT"), ("Plain", "POINT")):
        lamps[name] = gi_scenes._light(scene, name, kind, (0.0, -2.0, 3.0), target=(0, 0, 0),
                                       energy=50.0)
    lamps["Soft Box"].data.spread = math.radians(45.0)
    lamps["Fill"].data.use_shadow = False
    lamps["Linked"].light_linking.receiver_collection = bpy.data.collections.new("Lit")
    lamps["No Glint"].visible_glossy = False
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=32,
                                        resolution_y=24) == {"FINISHED"}
    report = [line for level, line in scene_session(scene.name_full).last_report
              if level == "WARNING" and line.startswith("Light '")]
    expected = {"Soft Box": "Spread of 45°", "Linked": "light linking",
                "No Glint": "hiding from glossy rays"}
    for name, what in expected.items():
        lines = [line for line in report if line.startswith(f"Light '{name}'")]
        assert len(lines) == 1 and what in lines[0] and "the preview leaves out" in lines[0], report
    assert not any(line.startswith(("Light 'Plain'", "Light 'Fill'")) for line in report), report
    layout = _Layout()
    bpy.types.VOXGI_PT_main.draw(type("PanelStub", (), {"layout": layout})(), bpy.context)
    assert "Light 'Soft Box':" in layout.labels, layout.labels


def test_shader_mixes_the_preview_shades_as_one_bsdf_are_named(voxgi):
    """An Add Shader of a Diffuse and a Glossy BSDF (shaded by its diffuse colour alone) and a
    Mix Shader of a Translucent and a Principled BSDF (with the Principled alone) are named;
    the mixes the preview reads as one mixed Principled BSDF (shader_mix: Diffuse and Glossy,
    two Principled BSDFs, a Glossy alone) and the cut-out mix of a Transparent BSDF and a
    Principled BSDF are not."""
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = bpy.context.scene

    def material(name, first, second=None, mixer="ShaderNodeMixShader"):
        made = bpy.data.materials.new(name)
        if made.node_tree is None:  # Blender < 5.0 creates materials without nodes
            made.use_nodes = True
        tree = made.node_tree
        for node in [n for n in tree.nodes if n.type != "OUTPUT_MATERIAL"]:
            tree.nodes.remove(node)
        surface = tree.nodes["Material Output"].inputs["Surface"]
        a = tree.nodes.new(first)
        if second is None:
            tree.links.new(a.outputs[0], surface)
            return made
        mix = tree.nodes.new(mixer)
        shaders = [s for s in mix.inputs if s.type == "SHADER"]
        tree.links.new(a.outputs[0], shaders[0])
        tree.links.new(tree.nodes.new(second).outputs[0], shaders[1])
        tree.links.new(mix.outputs[0], surface)
        return made

    quad = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    names = ("Varnish", "Blend", "Mirror", "Leaf", "Added", "Skin")
    for k, (name, made) in enumerate((
            ("Varnish", material("Varnish", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy")),
            ("Blend", material("Blend", "ShaderNodeBsdfPrincipled", "ShaderNodeBsdfPrincipled")),
            ("Mirror", material("Mirror", "ShaderNodeBsdfGlossy")),
            ("Leaf", material("Leaf", "ShaderNodeBsdfTransparent", "ShaderNodeBsdfPrincipled")),
            ("Added", material("Added", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
                               "ShaderNodeAddShader")),
            ("Skin", material("Skin", "ShaderNodeBsdfTranslucent", "ShaderNodeBsdfPrincipled")))):
        gi_scenes._mesh(scene, name, quad, [(0, 1, 2, 3)], (made,)).location.x = 3 * k
    warnings = take_snapshot(scene).warnings
    named = {name: [w for w in warnings if w.startswith(f"Object '{name}'")] for name in names}
    assert "Add Shader (the preview shades the surface by its diffuse colour alone" in \
        named["Added"][0]
    assert "Mix Shader (the preview shades the surface with one Principled BSDF" in \
        named["Skin"][0]
    for name in ("Varnish", "Blend", "Mirror", "Leaf"):
        assert named[name] == [], named[name]

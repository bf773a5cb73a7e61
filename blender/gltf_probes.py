"""Baked probe grids through Blender's own glTF exporter and importer (docs/gltf_probes.md
"Blender").

io_scene_gltf2 looks up ``glTF2ExportUserExtension`` / ``glTF2ImportUserExtension`` (and
``draw_import`` for the import dialog) on the top module of every enabled add-on when it runs;
the add-on's ``__init__`` hands out the classes below under those names. The export dialog's
panel is a draw function put into ``io_scene_gltf2.exporter_extension_layout_draw`` on
registration. The options live on the scene (``Scene.voxgi_gltf``), as the glTF add-on's own
user extensions keep theirs: **VoxGI Light Probes** on export (on by default: a scene with a
bake carries it) and on import.

Export (``gather_gltf_hook``, before the exporter turns its scene graph into indices): per
exported glTF scene whose Blender scene has grids, one node per grid, rotated Blender → glTF
when the export converts to +Y up (and shifted with "at collection center"), whose
``VOXGI_irradiance_volumes`` extension is a child-of-root extension: the exporter appends the
volume to the root extension's ``volumes`` and puts its accessors and bufferViews in its own
buffer (GLB chunk, .bin or data URI). ``gather_gltf_extensions_hook`` then writes each volume's
``node`` index, known only once the nodes are numbered.

Import (``gather_import_scene_after_nodes_hook``): the file is read again by the numpy decoder
(``voxgi_addon.files.gltf_probes``), which checks everything; the volumes whose nodes are in the
imported scene are mapped from their node's frame to Blender's world — exactly when that frame
is Blender's (what VoxGI writes), by translation and uniform scale otherwise; a rotated volume is
refused — and saved in the probe store, replacing grids of the same name. Any error is reported
to the user (the operator's report: an exception from ``bpy.ops``), names the volume and the
field, and leaves the store as it was; the rest of the scene imports as usual.
"""
from __future__ import annotations

import sys

import bpy
import numpy as np

from ..voxgi_addon.files import gltf_probes as fmt
from . import probe_store

EXTENSION = fmt.EXTENSION
# The add-on's top package ('voxgi' in the tests, 'bl_ext.<repo>.voxgi' installed): the key of its
# draw functions in io_scene_gltf2's dialog tables (the importer uses that key itself).
DRAW_KEY = __name__.rsplit(".", 2)[0]
IMPORTED_MARK = "voxgi_irradiance_volume"  # custom property of the Empty made of a volume's node
# glTF (x, y, z) → Blender (x, -z, y): the importer's axis conversion for +Y up files.
GLTF_TO_BLENDER = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], np.float64)


class VoxGIGltfSettings(bpy.types.PropertyGroup):
    export_probes: bpy.props.BoolProperty(
        name="VoxGI Light Probes",
        description="Write the scene's baked light probes as the VOXGI_irradiance_volumes extension "
                    "(only when the scene has a bake)",
        default=True)
    import_probes: bpy.props.BoolProperty(
        name="VoxGI Light Probes",
        description="Read VOXGI_irradiance_volumes into the scene's baked light probes",
        default=True)


def _settings(scene):
    return getattr(scene, "voxgi_gltf", None)


# --------------------------------------------------------------------------------------------
# Export


def draw_export(context, layout) -> None:
    """The export dialog's panel (io_scene_gltf2 calls it with the dialog's layout)."""
    settings = _settings(context.scene)
    if settings is None:
        return
    header, body = layout.panel("VOXGI_gltf_export_probes", default_closed=False)
    header.use_property_split = False
    header.prop(settings, "export_probes")
    if body is not None:
        grids = probe_store.load_grids(context.scene)
        probes = sum(len(g.positions) for g in grids)
        body.active = settings.export_probes
        body.label(text=f"{len(grids)} grid(s), {probes} probes" if grids else "No baked probes in this scene")


def _volume_node(gltf2_io, extensions, volume: dict, name: str, export_settings):
    y_up = export_settings.get("gltf_yup", True)
    center = None
    if export_settings.get("gltf_collection") and export_settings.get("gltf_at_collection_center"):
        center = export_settings.get("gltf_collection_center")
    translation = None
    if center is not None and any(float(c) != 0.0 for c in center):
        cx, cy, cz = (-float(c) for c in center)
        translation = [cx, cz, -cy] if y_up else [cx, cy, cz]
    extension = extensions.Extension(EXTENSION, {"volume": extensions.ChildOfRootExtension(
        ["volumes"], EXTENSION, volume, required=False)}, required=False)
    return gltf2_io.Node(camera=None, children=[], extensions={EXTENSION: extension}, extras=None,
                         matrix=None, mesh=None, name=name,
                         rotation=list(fmt.Y_UP_ROTATION) if y_up else None, scale=None, skin=None,
                         translation=translation, weights=None)


def _gltf_volume(enc: fmt.EncodedVolume, gltf2_io, binary_data) -> dict:
    """The volume's JSON with exporter objects where arrays go: the exporter's traversal puts
    each ``BinaryData`` in its buffer as a bufferView and numbers the accessors."""
    volume = dict(enc.properties)
    volume["node"] = -1  # set by gather_gltf_extensions_hook
    for name, (kind, count, data) in enc.accessors.items():
        volume[name] = gltf2_io.Accessor(
            buffer_view=binary_data.BinaryData(data), byte_offset=None, component_type=fmt.FLOAT,
            count=count, extensions=None, extras=None, max=None, min=None, name=None,
            normalized=None, sparse=None, type=kind)
    for name, data in enc.word_views.items():
        volume[name] = binary_data.BinaryData(data)
    return volume


class GltfExportProbes:
    """The exporter's user extension (``glTF2ExportUserExtension``); one per export."""

    def __init__(self):
        self.written: list[tuple[object, dict]] = []
        self.imported_markers: set[int] = set()

    def _log_error(self, export_settings, message):
        export_settings["log"].error(message, popup=True)

    def gather_node_hook(self, gltf2_node, blender_object, export_settings):
        if blender_object is not None and IMPORTED_MARK in blender_object.keys():
            self.imported_markers.add(id(gltf2_node))

    def gather_gltf_hook(self, active_scene_idx, scenes, animations, export_settings):
        try:
            self._add_volumes(active_scene_idx, scenes, export_settings)
        except Exception as error:  # noqa: BLE001 - the exporter would only log it to the console
            self._log_error(export_settings, f"VoxGI: the light probes are not exported: "
                            f"{type(error).__name__}: {error}")
            self.written = []

    def _add_volumes(self, active_scene_idx, scenes, export_settings):
        from io_scene_gltf2.io.com import gltf2_io
        from io_scene_gltf2.io.com import gltf2_io_extensions as extensions
        from io_scene_gltf2.io.exp import binary_data

        settings = _settings(bpy.context.scene)
        if settings is None or not settings.export_probes:
            return
        count = 0
        for gltf_scene in scenes:  # the Empties an import left for volumes: the volumes replace them
            gltf_scene.nodes = [n for n in gltf_scene.nodes
                                if id(n) not in self.imported_markers or n.children]
        for index, gltf_scene in enumerate(scenes):
            blender_scene = bpy.data.scenes.get(gltf_scene.name or "")
            if blender_scene is None and index == active_scene_idx:
                blender_scene = bpy.context.scene
            if blender_scene is None:
                continue
            grids = probe_store.load_grids(blender_scene)
            try:
                encoded = [fmt.encode_grid(g, i) for i, g in enumerate(grids)]
            except fmt.GltfProbesError as error:
                self._log_error(export_settings, f"VoxGI: the light probes of scene '{blender_scene.name}' "
                                f"are not exported: {error}")
                continue
            for i, enc in enumerate(encoded):
                volume = _gltf_volume(enc, gltf2_io, binary_data)
                name = fmt.node_name(enc.properties["name"], i)
                node = _volume_node(gltf2_io, extensions, volume, name, export_settings)
                gltf_scene.nodes.append(node)
                self.written.append((node, volume))
                count += 1
        if count:
            export_settings["log"].info(f"VoxGI: {count} light-probe volume(s) exported")

    def gather_gltf_extensions_hook(self, gltf, export_settings):
        for node, volume in self.written:
            index = next((i for i, n in enumerate(gltf.nodes) if n is node), None)
            if index is None:
                self._log_error(export_settings, f"VoxGI: the node of volume '{volume.get('name')}' "
                                "was dropped by the exporter")
                continue
            volume["node"] = index


# --------------------------------------------------------------------------------------------
# Import


def draw_import(context, layout) -> None:
    """The import dialog's panel (io_scene_gltf2 looks this name up on the add-on's module)."""
    settings = _settings(context.scene)
    if settings is None:
        return
    header, _body = layout.panel("VOXGI_gltf_import_probes", default_closed=False)
    header.use_property_split = False
    header.prop(settings, "import_probes")


def grid_to_blender(decoded: fmt.DecodedVolume, document: dict, y_up: bool = True):
    """The grid in Blender's world: unchanged (bit for bit) when its node's frame is Blender's
    world, else moved by the node's translation and uniform scale; raises ``GltfProbesError``
    for a node that rotates, shears or scales unevenly (VoxGI's grids are axis-aligned and SH
    directions are not rotated here)."""
    grid = decoded.grid
    where = f"volume {decoded.index} '{grid.name}'" if grid.name else f"volume {decoded.index}"
    m = fmt.node_world_matrix(document, decoded.node)
    if y_up:
        m = GLTF_TO_BLENDER @ m
    if np.allclose(m, np.eye(4), rtol=0.0, atol=1e-6):
        return grid
    linear = m[:3, :3]
    scale = float(np.cbrt(np.linalg.det(linear))) if np.linalg.det(linear) > 0 else 0.0
    if scale <= 0 or not np.allclose(linear, scale * np.eye(3), rtol=0.0, atol=1e-6 * max(scale, 1.0)):
        raise fmt.GltfProbesError(where, "node", f"nodes[{decoded.node}] rotates, mirrors or scales the "
                                  "volume unevenly against the scene's axes; VoxGI reads axis-aligned "
                                  "volumes only")
    offset = m[:3, 3]
    grid.origin = grid.origin * scale + offset
    grid.volume_size = grid.volume_size * scale
    grid.positions = (grid.positions.astype(np.float64) * scale + offset).astype(np.float32)
    return grid


class GltfImportProbes:
    """The importer's user extension (``glTF2ImportUserExtension``); one per import."""

    def gather_import_node_after_hook(self, vnode, gltf_node, blender_object, gltf):
        """Mark the Empty the importer makes of a volume's node (a re-export drops it)."""
        ext = getattr(gltf_node, "extensions", None) or {}
        if blender_object is not None and isinstance(ext.get(EXTENSION), dict):
            blender_object[IMPORTED_MARK] = int(ext[EXTENSION].get("volume", -1))

    def gather_import_scene_after_nodes_hook(self, gltf_scene, blender_scene, gltf):
        try:
            self._read_volumes(blender_scene, gltf)
        except Exception as error:  # noqa: BLE001 - the importer would only log it to the console
            gltf.log.error(f"VoxGI: the light probes in '{gltf.filename}' are not imported: "
                           f"{type(error).__name__}: {error}", popup=True)

    def _read_volumes(self, blender_scene, gltf):
        extensions = getattr(gltf.data, "extensions", None) or {}
        if EXTENSION not in extensions:
            return
        settings = _settings(blender_scene)
        if settings is not None and not settings.import_probes:
            return
        try:
            file = fmt.read_gltf(gltf.filename)
            decoded = fmt.decode_volumes(file)
            in_scene = fmt.scene_nodes(file.document, file.document.get("scene"))
            # Blender's importer always converts glTF's +Y up to +Z up
            grids = [grid_to_blender(d, file.document) for d in decoded if d.node in in_scene]
        except fmt.GltfProbesError as error:
            gltf.log.error(f"VoxGI: the light probes in '{gltf.filename}' are not imported: {error}",
                           popup=True)
            return
        except OSError as error:
            gltf.log.error(f"VoxGI: cannot read '{gltf.filename}' for its light probes: {error}", popup=True)
            return
        if not grids:
            return
        names = {g.name for g in grids}
        kept = [g for g in probe_store.load_grids(blender_scene) if g.name not in names]
        probe_store.save_grids(blender_scene, kept + grids)
        gltf.log.info(f"VoxGI: {len(grids)} light-probe volume(s) imported into scene "
                      f"'{blender_scene.name}'", popup=True)


# --------------------------------------------------------------------------------------------
# Registration


def _gltf_addon():
    try:
        import io_scene_gltf2
    except ImportError:
        return None
    return io_scene_gltf2


def register() -> None:
    bpy.types.Scene.voxgi_gltf = bpy.props.PointerProperty(type=VoxGIGltfSettings)
    addon = _gltf_addon()
    if addon is not None and hasattr(addon, "exporter_extension_layout_draw"):
        addon.exporter_extension_layout_draw[DRAW_KEY] = draw_export


def unregister() -> None:
    addon = sys.modules.get("io_scene_gltf2")
    if addon is not None:
        getattr(addon, "exporter_extension_layout_draw", {}).pop(DRAW_KEY, None)
        getattr(addon, "importer_extension_layout_draw", {}).pop(DRAW_KEY, None)
    if hasattr(bpy.types.Scene, "voxgi_gltf"):
        del bpy.types.Scene.voxgi_gltf


classes = (VoxGIGltfSettings,)

# The names io_scene_gltf2 looks for (the add-on's __init__ hands these out).
glTF2ExportUserExtension = GltfExportProbes
glTF2ImportUserExtension = GltfImportProbes

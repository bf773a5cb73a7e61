"""The Blender side's services (bpy, main thread): everything operators, the render engine and
the panels share, and nothing that registers an operator or a panel.

  settings         ``Scene.voxgi`` (the PropertyGroup) and its conversion to engine settings
  viewport_settings ``Scene.voxgi_viewport``: viewport resolution, pass shown, debug views
  session          per-scene results kept out of ID properties
  viewport_session live viewport GI: plans depsgraph updates, runs them on the worker
  updates          depsgraph updates as records, what changed since a snapshot, posed snapshots
  probe_store      baked probe grids kept with the .blend (a Text datablock), bake progress
  gltf_probes      the probe grids in Blender's glTF exporter/importer (VOXGI_irradiance_volumes)
  jobs             the engine worker thread, its queue, timer and progress
  snapshot/        reading the scene into the engine's ``SceneSnapshot``
  reports          report lines and tables of results
  operator_poll    the poll shared by scene operators
  scene_building   bpy helpers that build materials, meshes and bones from data
  demo_scene       the demo Cornell box
  gfg/             GFG scene export and import (bpy ↔ ``voxgi_addon.files.gfg``)
"""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import gltf_probes, jobs, session, settings, updates, viewport_session, viewport_settings
from .snapshot import materials as snapshot_materials
from .snapshot import world_map

# Registered in this order (settings first), unregistered in reverse (jobs stop before the
# sessions are cleared; the world maps' cache goes last).
modules = (world_map, snapshot_materials, settings, viewport_settings, session, updates,
           viewport_session, jobs, gltf_probes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)

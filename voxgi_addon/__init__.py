"""VoxGI engine: numpy only, never imports bpy (runs on the worker thread and in pytest).

Modules, one concept each:
  snapshot          the scene description the engine reads
  mesh_checks       dropping NaN / zero-area triangles
  object_scale      rigid part vs scale to bake
  triangle_box      exact triangle/box overlap (reference)
  voxelize          conservative surface voxelization
  voxel_attributes  per-voxel albedo / normal / specular / skin weights
  voxel_packing     the thesis' packed words
  voxel_cache       VoxelCache
  mesh_caches       the scene voxelization job
  gfg/              GFG-like asset files: spec, writer, reader, CLI (docs/gfg.md)
"""

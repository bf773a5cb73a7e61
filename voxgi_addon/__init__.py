"""VoxGI engine: numpy only, never imports bpy (runs on the worker thread and in pytest).

Modules, one concept each, in the order data flows through them:
  snapshot          the scene description the engine reads
  errors            VoxGIError (bad input) and VoxGICancelled
  mesh_checks       dropping NaN / zero-area triangles
  object_scale      rigid part vs scale to bake
  triangle_box      exact triangle/box overlap (the reference)
  voxelize          conservative surface voxelization
  cube_clipping     exact clipping of triangles and planes to voxel cubes
  voxel_attributes  per-voxel albedo / normal / specular / plane offset / skin weights
  voxel_packing     the thesis' packed words
  voxel_cache       VoxelCache
  mesh_caches       the scene voxelization job
  skinning          linear blend skinning matrices
  cascades          camera-anchored nested grids; cache → world voxels (no re-voxelization)
  voxel_shadows     shadow rays through cascade occupancy
  direct_light      Cycles' light models (Diffuse Direct units)
  voxel_lighting    direct light injected into cascade voxels
  morton            Morton keys
  svo, svo_sampling the semi-sparse voxel octree and its (anisotropic) trilinear sampling
  gi_update         one update: cascades → light → octree
  conetrace         diffuse / AO / glossy / shadow cones
  scene_geometry    the scene's world-space triangles
  raycast           exact ray casting (primary visibility, shadows)
  preview           the camera's Cycles-named passes
  exr, png          image files
  gfg/              GFG-like asset files: spec, writer, reader, CLI (docs/gfg.md)
"""

"""VoxGI engine: numpy only, never imports bpy/gpu (runs on the worker thread and in pytest).

Subpackages are the pipeline's stages, in the order data flows through them:

  scene/      the input: ``snapshot`` (the scene description the engine reads), ``skinning``,
              ``geometry`` (world-space triangles), ``camera`` (pixel rays, projection),
              ``raycast`` (exact ray casting)
  voxelize/   once per mesh: ``mesh_checks`` → ``object_scale`` → ``surface`` (conservative
              voxelization; ``triangle_box`` is the exact test) → ``cube_clipping`` →
              ``attributes`` → ``packing`` (the thesis' words) → ``cache`` (VoxelCache);
              ``scene_caches`` runs it for a whole snapshot
  gi/         every update: ``cascades`` (caches → nested world grids) → ``direct_light``
              (Cycles' light models) and ``voxel_shadows`` → ``light_injection`` → ``morton``,
              ``svo``, ``svo_sampling`` (the octree) → ``conetrace``, ``cone_shadows`` (the
              reference tracer); ``update`` is one update end to end
  probes/     light probes (Bowald 2016): ``sh``, ``placement`` → ``validity`` → ``masks`` →
              ``bake`` (or ``octree_bake``) → ``query``; ``grid`` (the baked grid), ``store``
  preview/    the camera's passes: ``passes`` (Cycles-named passes), ``upsample``, and the GPU
              data layouts ``trace_params`` and ``volume_textures`` (plain numpy)
  files/      ``exr``, ``png`` and ``gfg/`` (GFG-like asset files, docs/gfg.md)

``errors`` holds VoxGIError (bad input) and VoxGICancelled, shared by every stage.
"""

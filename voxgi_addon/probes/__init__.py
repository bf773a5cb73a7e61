"""Light-probe authoring after Bowald 2016, ch. 3 (docs/probes.md), in data-flow order:

  ``sh``         SH L2 basis, seeded sample directions, projection, cosine-lobe irradiance
  ``grid``       ``ProbeGrid``: the baked grid and Bowald's index arrays, memory report
  ``placement``  volumes with geometry (exact triangle/box test) and their corner probes
  ``validity``   back-face share of each probe's rays; relocation or disabling
  ``masks``      per corner probe, the 64-bit mask of the 4×4×4 sub-volumes it may light
  ``direct``     the world's and the emissive surfaces' light straight at a probe (next-event
                 estimation, multiple importance sampling with the bake's directions)
  ``bake``       ``bake_probe_grid``: the stages above and the exact one-bounce radiance
  ``octree_bake`` the same SH from the voxel octree's cone march (the GPU bake's reference)
  ``query``      irradiance at points and normals through the index arrays, trilinear
  ``store``      a grid list ↔ compact bytes (a GFG file of PRBG sections, compressed)
"""

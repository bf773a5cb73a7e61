"""Voxelization, once per mesh and cascade span: checks, conservative surface voxelization,
per-voxel attributes and the packed voxel caches (docs/gi_pipeline.md)."""

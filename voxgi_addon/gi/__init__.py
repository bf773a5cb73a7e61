"""One GI update: cascades from the caches, direct light injected, the octree rebuilt, and the
numpy reference cone tracer (docs/gi_pipeline.md)."""

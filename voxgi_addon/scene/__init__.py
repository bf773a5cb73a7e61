"""The engine's input: the scene snapshot and what is computed straight from it (skinned and
world-space triangles, the camera model, exact ray casting)."""

/* G-buffer pass: world-space triangles projected with the camera's view_projection. The
 * vertex attributes depend on the triangles only (render/gbuffer.py keeps their batch); the
 * texel densities (texel.y, glow.z, per metre) are scaled here by `pixel_spread`, a pixel's
 * footprint at unit distance for this camera, image size and Filter Size. */
void main()
{
  world_position = position;
  shading_normal = normal;
  flat_normal = face_normal;
  surface = material;
  surface_uv = uv;
  surface_slot = vec2(texel.x, texel.y * pixel_spread);
  surface_cutout = cutout;
  surface_params = params;
  surface_normal_map = normal_map;
  surface_tangent = tangent;
  surface_glow = vec4(glow.x, glow.y, glow.z * pixel_spread, glow.w);
  surface_base = material_base;
  gl_Position = view_projection * vec4(position, 1.0);
}

/* G-buffer pass: world-space triangles projected with the camera's view_projection. */
void main()
{
  world_position = position;
  shading_normal = normal;
  flat_normal = face_normal;
  surface = material;
  surface_uv = uv;
  surface_slot = texel;
  surface_cutout = cutout;
  surface_params = params;
  surface_normal_map = normal_map;
  surface_tangent = tangent;
  surface_glow = glow;
  surface_base = material_base;
  gl_Position = view_projection * vec4(position, 1.0);
}

/* G-buffer pass: what raycast.primary_visibility returns per pixel, bottom row first.
 * out_position: world xyz, 1 (hit); out_normal: shading normal turned to the camera (by the
 * face normal, as Cycles does), roughness; out_view: camera → point unit direction, material. */
void main()
{
  vec3 view = camera_ortho > 0.5 ? camera_forward : normalize(world_position - camera_position);
  float facing = dot(flat_normal, view) > 0.0 ? -1.0 : 1.0;
  vec3 n = shading_normal;
  n = dot(n, n) > 1e-24 ? normalize(n) : flat_normal;
  out_position = vec4(world_position, 1.0);
  out_normal = vec4(n * facing, surface.y);
  out_view = vec4(view, surface.x);
}

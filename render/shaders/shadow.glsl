/* Soft-shadow visibility of one light per pixel (conetrace.trace_shadow): one cone from the
 * lifted surface point to the light, wide enough to cover its radius, its samples no wider
 * than 2/3 of their height above the surface; out = (1 − occlusion).
 * light_position.xyz: a point light's centre, or the direction towards a sun (w = 1);
 * light_size.x: the light's radius in metres, or for a sun the tangent of its half-angle. */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  load_params();
  if (px.x >= imageSize(out_image).x || px.y >= imageSize(out_image).y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec4 s1 = param(ROW_SETTINGS + 1);
  float height = s1.z * local_voxel_size(position.xyz);
  vec3 origin = position.xyz + n * height;
  vec3 target = light_position.xyz;
  float radius = max(light_size.x, 1e-3);
  if (light_position.w > 0.5) {  /* a sun: a point max_distance away in its direction */
    target = origin + light_position.xyz * s1.x;
    radius = light_size.x * s1.x;
  }
  vec3 to_light = target - origin;
  float dist = length(to_light);
  vec3 axis = to_light / max(dist, 1e-12);
  radius = max(radius, 1e-3);
  float tan_half = tan(atan(radius / max(dist, 1e-6)));
  /* Stop short of the light: the surface it is mounted on must not shadow it. */
  float reach = max(dist - max(radius, 2.0 * local_voxel_size(target)), 0.0);
  vec3 radiance;
  float alpha_light, alpha_occlusion;
  /* no sample reads nodes wider than 2/3 of its height above the surface (as diffuse_ao) */
  march(origin, axis, tan_half, local_voxel_size(origin), 0.0, reach, 0.0, true, n, height,
        radiance, alpha_light, alpha_occlusion);
  imageStore(out_image, px, vec4(1.0 - alpha_occlusion));
}

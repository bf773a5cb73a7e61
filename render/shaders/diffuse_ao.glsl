/* Diffuse indirect (rgb, light without albedo) and ambient occlusion (a) per traced pixel
 * (conetrace.trace_diffuse_and_ao): the cone set around the normal, each cone marching light
 * to max_distance and occlusion to ao_distance on the same samples; the light is one bounce's
 * (the emission octree's colour subtracted, no world).
 * sampling.w = 1: what the cones see of the world instead (conetrace.trace_world_visibility):
 * rgb = Σ w T L_world, a = Σ w lum(L_world), T each cone's transmittance at its end.
 * One invocation per low-resolution cell: sampling = (stride, full width, full height); the
 * cell traces the G-buffer pixel gi_upsample.sample_pixels picks (rows counted from the top
 * there, from the bottom here). */
void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  load_params();
  ivec2 low = imageSize(out_image);
  if (cell.x >= low.x || cell.y >= low.y) {
    return;
  }
  int stride = int(sampling.x);
  ivec2 full = ivec2(sampling.yz);
  ivec2 px = traced_pixel(low.y - 1 - cell.y, cell.x, stride, full);
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, cell, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec4 s0 = param(ROW_SETTINGS);
  vec4 s1 = param(ROW_SETTINGS + 1);  /* max_distance, ao_distance, start_offset, tan(half angle) */
  vec4 s2 = param(ROW_SETTINGS + 2);  /* anisotropic, cone count, gi_intensity, ao_intensity */
  float height = s1.z * local_voxel_size(position.xyz);
  vec3 origin = position.xyz + n * height;
  float local = local_voxel_size(origin);
  vec3 t, s;
  tangent_frame(n, t, s);
  vec3 diffuse = vec3(0.0);
  float visible = 0.0;
  bool world_mode = sampling.w > 0.5;
  g_subtract_emission = !world_mode;
  g_want_colour = !world_mode;
  if (world_mode) {
    load_world();
  }
  float half_angle = atan(s1.w);
  for (int k = 0; k < int(s2.y); k++) {
    vec4 cone = param(ROW_CONES + k);  /* local axis xyz, weight */
    vec3 axis = t * cone.x + s * cone.y + n * cone.z;
    vec3 radiance;
    float alpha_light, alpha_occlusion;
    march(origin, axis, s1.w, local, s1.x, world_mode ? 0.0 : s1.y, s0.z, true, n, height,
          radiance, alpha_light, alpha_occlusion);
    if (world_mode) {
      vec3 sky = world_radiance(axis, half_angle);
      diffuse += cone.w * (1.0 - alpha_light) * sky;
      visible += cone.w * dot(sky, vec3(0.2126, 0.7152, 0.0722));
      continue;
    }
    diffuse += cone.w * radiance;
    visible += cone.w * (1.0 - alpha_occlusion);
  }
  if (world_mode) {
    imageStore(out_image, cell, vec4(diffuse, visible));
    return;
  }
  float ao = 1.0 - clamp(s2.w * (1.0 - visible), 0.0, 1.0);
  imageStore(out_image, cell, vec4(s2.z * diffuse, ao));
}

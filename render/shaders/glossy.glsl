/* Glossy indirect (rgb) per traced pixel (conetrace.trace_glossy): one cone along the mirror
 * direction of the view ray, its half-angle from the roughness (gbuffer_normal.w); it sees the
 * voxels' emission, and the world (its remaining transmittance × world_radiance). One
 * invocation per low-resolution cell, as diffuse_ao.glsl (sampling = stride, full size). */
void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  load_params();
  ivec2 low = imageSize(out_image);
  if (cell.x >= low.x || cell.y >= low.y) {
    return;
  }
  ivec2 px = traced_pixel(low.y - 1 - cell.y, cell.x, int(sampling.x), ivec2(sampling.yz));
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, cell, vec4(0.0));
    return;
  }
  vec4 normal = texelFetch(gbuffer_normal, px, 0);
  vec3 n = normal.xyz;
  vec3 view = texelFetch(gbuffer_view, px, 0).xyz;
  vec4 s1 = param(ROW_SETTINGS + 1);
  vec4 s2 = param(ROW_SETTINGS + 2);
  vec3 reflected = view - 2.0 * dot(view, n) * n;
  vec3 origin = position.xyz + n * (s1.z * local_voxel_size(position.xyz));
  float r = clamp(normal.w, 0.0, 1.0);
  float half_angle = clamp(atan(r * r * 1.5), radians(1.0), radians(60.0));
  vec3 radiance;
  float alpha_light, alpha_occlusion;
  march(origin, reflected, tan(half_angle), local_voxel_size(origin), s1.x, 0.0, 0.0, false, n, 0.0,
        radiance, alpha_light, alpha_occlusion);
  load_world();
  radiance += (1.0 - alpha_light) * world_radiance(reflected, half_angle);
  imageStore(out_image, cell, vec4(s2.z * radiance, 1.0));
}

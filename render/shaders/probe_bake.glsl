/* Probe bake, pass 1 (voxgi_addon/probes/octree_bake.py is the numpy statement): one narrow
 * cone per (probe, direction) pair through the octree's injected light.
 * out pixel (x, y) → pair y·width + x → probe pair / N, direction pair % N.
 * probe_positions: probe j at texel (j % 4096, j / 4096), xyz; probe_dirs: direction i at (i, 0).
 * sampling = (N, P, start_offset, tan(half-angle)); world = (rgb, max distance).
 * Output: radiance rgb (world colour where the cone stays open), light alpha. */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  load_params();
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  int n = int(sampling.x);
  int pair = px.y * size.x + px.x;
  int probe = pair / n;
  if (probe >= int(sampling.y)) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 p = texelFetch(probe_positions, ivec2(probe % 4096, probe / 4096), 0).xyz;
  vec3 dir = texelFetch(probe_dirs, ivec2(pair % n, 0), 0).xyz;
  vec3 origin = p + dir * (sampling.z * local_voxel_size(p));
  vec3 radiance;
  float alpha_light;
  float alpha_occlusion;
  march(origin, dir, sampling.w, local_voxel_size(origin), world.w, 0.0, 0.0, false, dir, 0.0,
        radiance, alpha_light, alpha_occlusion);
  imageStore(out_image, px, vec4(radiance + (1.0 - alpha_light) * world.rgb, alpha_light));
}

/* One iteration of the radiance cache (voxgi_addon/gi/radiance_cache.py relax): voxel face f
 * (texel (f mod W, f div W) of out_image) gets the mean over its rays' records
 * (cache_paths.glsl, record i = f · rays + j at texel (i mod Wr, i div Wr) of paths_*) of
 * radiance + cache weight × the previous iteration's cache at the hit (cache_lookup.glsl).
 * sampling = (rays per face, faces, 0, 0). */

void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  int face = texel.y * size.x + texel.x;
  if (texel.x >= size.x || texel.y >= size.y || face >= int(sampling.y)) {
    return;
  }
  int rays = int(sampling.x);
  int width = textureSize(paths_radiance, 0).x;
  vec3 sum = vec3(0.0);
  for (int j = 0; j < rays; j++) {
    int record = face * rays + j;
    ivec2 at = ivec2(record % width, record / width);
    vec4 radiance = texelFetch(paths_radiance, at, 0);
    sum += radiance.rgb;
    if (radiance.a > 0.5) {
      sum += texelFetch(paths_weight, at, 0).rgb *
             cache_indirect(texelFetch(paths_points, at, 0).xyz,
                            texelFetch(paths_normals, at, 0).xyz);
    }
  }
  imageStore(out_image, texel, vec4(sum / float(rays), 0.0));
}

/* One iteration of the radiance cache (voxgi_addon/gi/radiance_cache.py relax), written as the
 * next iteration's texels (radiance_cache.cache_texels) from `cache_layout` (the same texels
 * with (face row, 0, 0, held) in place of the light: cache_texels(layout=True)): row 0 (the
 * header) is copied; a held face f gets (the mean over its rays' records (cache_paths.glsl,
 * record i = f · rays + j at texel (i mod Wr, i div Wr) of paths_*) of radiance + cache weight
 * × the previous iteration's cache at the hit (cache_lookup.glsl), 1); the other texels 0.
 * sampling = (rays per face, 1: the layout has two parts (cache_texels(layout=True,
 * ahead=True)): part 0's texels are the previous iteration's, copied, and part 1's the next
 * one's, which the glossy gather reads, 0, 0). */

void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (texel.x >= size.x || texel.y >= size.y) {
    return;
  }
  vec4 held = texelFetch(cache_layout, texel, 0);
  if (texel.y == 0 || held.w < 0.5) {
    imageStore(out_image, texel, held);  /* the header, or an empty texel */
    return;
  }
  if (sampling.y > 0.5 && held.y < 0.5) {
    imageStore(out_image, texel, texelFetch(radiance_cache, texel, 0)); /* the previous one */
    return;
  }
  int face = int(held.x + 0.5);
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
  imageStore(out_image, texel, vec4(sum / float(rays), 1.0));
}

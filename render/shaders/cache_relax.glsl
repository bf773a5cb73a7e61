/* One iteration of the radiance cache (voxgi_addon/gi/radiance_cache.py relax), an invocation
 * per voxel face: face f = (row · width + column) of `face_places` (render/gpu_gather.py
 * face_places: its texel of the cache's texels, radiance_cache.cache_texels, and of their
 * ahead part) gets (the mean over its rays' records (cache_paths.glsl, record i = f · rays + j
 * at texel (i mod Wr, i div Wr) of paths_*) of radiance + cache weight × the previous
 * iteration's value at the face the ray picked (paths_pick .w: a compact index, -1 none;
 * the face's lone outlier record's radiance tamed first, radiance_cache.tamed;
 * radiance_cache.picks), 1) at its texel of out_image: one texel per ray, no lookup
 * (docs/gi_pipeline.md "Multi-bounce radiance cache", "Each ray picks one face"). The other
 * texels of out_image (the header, the ids, the voxels' absent faces) are the layout's,
 * uploaded once. sampling = (rays per face, 1: out_image has two parts (cache_texels(ahead=
 * True)): the face's texel of part 0 keeps the previous iteration, of part 1 gets the next
 * one, faces, 1: radiance_cache is the empty cache (the first
 * iteration: the records' radiance alone)). levels = (1: cache_level holds this iteration's
 * first pass, the part of copy_image this iteration is also written to (0: none), 0, 0). */

void main()
{
  ivec2 id = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = textureSize(face_places, 0);
  int face = id.y * size.x + id.x;
  if (id.x >= size.x || id.y >= size.y || face >= int(sampling.z)) {
    return;
  }
  vec4 place = texelFetch(face_places, id, 0);
  int rays = int(sampling.x);
  int width = textureSize(paths_radiance, 0).x;
  ivec2 cache_size = textureSize(radiance_cache, 0);
  vec4 info = texelFetch(radiance_cache, ivec2(cache_size.x - 1, 0), 0);
  int first_row = 1 + int(info.y + 0.5) * int(info.x + 0.5);
  bool empty = sampling.w > 0.5;
  bool estimate = levels.x > 0.5;
  vec3 sum = vec3(0.0);
  /* the brightest record's own light, its largest channel, whether its hit is a metal, and the
   * second brightest's largest channel: a lone outlier off a metal is tamed
   * (radiance_cache.tamed) */
  vec3 top_rgb = vec3(0.0);
  float top = -1.0, second = -1.0;
  bool top_metal = false;
  for (int j = 0; j < rays; j++) {
    int record = face * rays + j;
    ivec2 at = ivec2(record % width, record / width);
    vec4 lit = texelFetch(paths_radiance, at, 0);
    /* .a: the glossy share of the record's weight, stored as −(1 + it) where its hit is a
     * metal (cache_paths.glsl) */
    bool metal = lit.a < -0.5;
    lit.a = metal ? -lit.a - 1.0 : lit.a;
    sum += lit.rgb;
    float peak = max(lit.r, max(lit.g, lit.b));
    if (peak > top) {
      second = top;
      top = peak;
      top_rgb = lit.rgb;
      top_metal = metal;
    }
    else if (peak > second) {
      second = peak;
    }
    vec4 picked = texelFetch(paths_pick, at, 0);
    if (picked.w > -0.5) {
      int t = int(picked.w + 0.5);
      ivec2 c = ivec2(t % cache_size.x, first_row + t / cache_size.x);
      vec3 before = empty ? vec3(0.0) : texelFetch(radiance_cache, c, 0).rgb;
      vec3 same = estimate ? texelFetch(cache_level, c, 0).rgb : before;
      sum += picked.rgb * mix(before, same, lit.a);
    }
  }
  float most = max(OUTLIER_FLOOR, OUTLIER_RATIO * max(second, 0.0));
  if (top > most && top_metal) {
    sum -= top_rgb * (1.0 - most / top);
  }
  vec4 value = vec4(sum / float(rays), 1.0);
  ivec2 texel = ivec2(place.xy + 0.5);
  if (sampling.y > 0.5) {
    /* the previous one, its .a 1 + how much more light the next one carries */
    vec3 before = texelFetch(radiance_cache, texel, 0).rgb;
    float lit = dot(before, vec3(1.0));
    float more = lit > 0.0 ? max(dot(value.rgb, vec3(1.0)) - lit, 0.0) / lit : 0.0;
    imageStore(out_image, texel, vec4(before, 1.0 + more));
    imageStore(out_image, ivec2(place.zw + 0.5), value);
  }
  else {
    imageStore(out_image, texel, value);
  }
  if (levels.y > 0.5) {
    /* this iteration kept in copy_image's part levels.y too (part 0's texel + that many
     * parts' texels: V voxels × 6 faces each; radiance_cache.cache_levels) */
    int t = (texel.y - first_row) * cache_size.x + texel.x +
            int(levels.y + 0.5) * 6 * int(info.w + 0.5);
    imageStore(copy_image, ivec2(t % cache_size.x, first_row + t / cache_size.x), value);
  }
}

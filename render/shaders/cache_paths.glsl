/* The radiance cache's rays, traced and lit once (voxgi_addon/gi/radiance_cache.py face_paths,
 * exact_indirect.ray_paths), each hit's face of the cache picked once (radiance_cache.picks):
 * ray j of voxel face f is record i = f · rays + j, at texel (i mod W, i div W) of the W-wide
 * outputs. The faces: gbuffer_position (origin xyz, 1) and gbuffer_normal (unit axis) at texel
 * (f mod Wf, f div Wf), sample id f (face_points' row). radiance_cache : the layout's texels
 * (radiance_cache.cache_texels: the grids' ids and the faces each voxel holds).
 * out_image = (the ray's radiance without the cache rgb, the glossy share of its weight;
 *              −(1 + it) where the hit is a metal: cache_relax.glsl tames a face's lone
 *              outlier off a metal, radiance_cache.tamed) (bvh_shade.glsl ray_paths)
 * out_pick  = (the hit's cache weight rgb, the face its lookup reads: cache_pick's compact
 *              index, drawn by the record's hash of stream CACHE_PICK_STREAM; -1 on a miss
 *              or where the lookup reads 0)
 * Push constants:
 *   sampling = (seed, rays per face, faces, strata side m of the hit's light samples)
 *   world    = rgb radiance of a miss, w: 1 = the hit's glossy lobe reflects the lights too
 *   chunk    = (first output row of this dispatch, end row, 0, 0) */

void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, int(chunk.x));
  ivec2 size = imageSize(out_image);
  if (texel.x >= size.x || texel.y >= min(size.y, int(chunk.y))) {
    return;
  }
  int rays = int(sampling.y);
  int record = texel.y * size.x + texel.x;
  int face = record / rays;
  int j = record - face * rays;
  if (face >= int(sampling.z)) {
    return;
  }
  int face_width = textureSize(gbuffer_position, 0).x;
  ivec2 at = ivec2(face % face_width, face / face_width);
  vec3 position = texelFetch(gbuffer_position, at, 0).xyz;
  vec3 n = texelFetch(gbuffer_normal, at, 0).xyz;
  uint seed = uint(sampling.x);
  uint id = uint(face);
  vec3 origin = position + surface_offset(position, SURFACE_EPSILON) * n;
  uint state = point_stream(id, RAY_STREAM, seed);
  vec3 t, b;
  perpendicular_basis(n, t, b);
  vec2 disk = concentric_disk(hammersley(state, j, rays));
  float z = sqrt(max(0.0, 1.0 - dot(disk, disk)));
  vec3 d = normalize(disk.x * t + disk.y * b + z * n);
  float th = BVH_FAR;
  vec3 x, ns, weight, glossy;
  uint hit_id = id * uint(rays) + uint(j);
  /* A metal hit is followed one reflection further (radiance_cache.follow_metals): one loop
   * for both hits, so the second's code is compiled once and runs only where a lane meets a
   * metal (as bvh_shade.glsl ray_radiance). */
  bool metal = false;
  vec3 radiance = vec3(0.0);
  vec3 second_weight = vec3(0.0), second_glossy = vec3(0.0);
  vec3 x2 = vec3(0.0), ns2 = vec3(0.0);
  vec3 o = origin;
  vec3 dir = d;
  for (int step = 0; step < 2; step++) {
    bool first = step == 0;
    float t_hit;
    vec3 px, pn, pw, pg;
    radiance += (first ? vec3(1.0) : glossy) *
                ray_paths(o, dir, first ? hit_id : pcg_hash(hit_id ^ CONTINUE_STREAM), seed,
                          first ? int(sampling.w) : 1, first ? world.w > 0.5 : true,
                          first ? world.rgb : vec3(0.0), false, t_hit, px, pn, pw, pg);
    if (first) {
      th = t_hit;
      x = x2 = px;
      ns = ns2 = pn;
      weight = pw;
      glossy = pg;
      if (t_hit >= BVH_FAR || hit_metallic < METAL_FOLLOWED) {
        break;
      }
      metal = true;
      if (!metal_follow(x, ns, d, hit_id, seed, o, dir)) {
        break;
      }
      continue;
    }
    if (t_hit < BVH_FAR) {
      second_weight = glossy * pw;
      second_glossy = glossy * pg;
      x2 = px;
      ns2 = pn;
    }
    break;
  }
  if (metal) {
    /* the record reads one face: the first hit's for its diffuse share, or the second hit's
     * for the Glossy Color × that hit's weight, chosen by their sums, divided by its chance */
    vec3 diffuse = weight - glossy;
    float a_sum = dot(diffuse, vec3(1.0));
    float b_sum = dot(second_weight, vec3(1.0));
    float u = unit_float(point_stream(uint(record), CONTINUE_STREAM + 1u, seed));
    if (u * (a_sum + b_sum) < a_sum) {
      weight = diffuse * ((a_sum + b_sum) / max(a_sum, 1e-30));
      glossy = vec3(0.0);
    }
    else {
      float scale = (a_sum + b_sum) / max(b_sum, 1e-30);
      weight = second_weight * scale;
      glossy = second_glossy * scale;
      x = x2;
      ns = ns2;
    }
  }
  float picked = -1.0;
  if (th < BVH_FAR) {
    uint pick_state = point_stream(uint(record), CACHE_PICK_STREAM, seed);
    picked = cache_pick(x, ns, unit_float(pick_state));
  }
  float share = dot(glossy, vec3(1.0)) / max(dot(weight, vec3(1.0)), 1e-30);
  imageStore(out_image, texel, vec4(radiance, metal ? -1.0 - share : share));
  imageStore(out_pick, texel, vec4(picked < 0.0 ? vec3(0.0) : weight, picked));
}

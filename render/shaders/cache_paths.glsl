/* The radiance cache's rays, traced and lit once (voxgi_addon/gi/radiance_cache.py face_paths,
 * exact_indirect.ray_paths), each hit's face of the cache picked once (radiance_cache.picks):
 * ray j of voxel face f is record i = f · rays + j, at texel (i mod W, i div W) of the W-wide
 * outputs. The faces: gbuffer_position (origin xyz, 1) and gbuffer_normal (unit axis) at texel
 * (f mod Wf, f div Wf), sample id f (face_points' row). radiance_cache : the layout's texels
 * (radiance_cache.cache_texels: the grids' ids and the faces each voxel holds).
 * out_image = (the ray's radiance without the cache rgb, 0)      (bvh_shade.glsl ray_paths)
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
  vec3 origin = position + SURFACE_EPSILON * n;
  uint state = point_stream(id, RAY_STREAM, seed);
  vec3 t, b;
  perpendicular_basis(n, t, b);
  vec2 disk = concentric_disk(hammersley(state, j, rays));
  float z = sqrt(max(0.0, 1.0 - dot(disk, disk)));
  vec3 d = normalize(disk.x * t + disk.y * b + z * n);
  float th;
  vec3 x, ns, weight, glossy;
  vec3 radiance = ray_paths(origin, d, id * uint(rays) + uint(j), seed, int(sampling.w),
                            world.w > 0.5, world.rgb, false, th, x, ns, weight, glossy);
  float picked = -1.0;
  if (th < BVH_FAR) {
    uint pick_state = point_stream(uint(record), CACHE_PICK_STREAM, seed);
    picked = cache_pick(x, ns, unit_float(pick_state));
  }
  imageStore(out_image, texel, vec4(radiance, dot(glossy, vec3(1.0)) / max(dot(weight, vec3(1.0)), 1e-30)));
  imageStore(out_pick, texel, vec4(picked < 0.0 ? vec3(0.0) : weight, picked));
}

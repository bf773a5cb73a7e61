/* The radiance cache's rays, traced and lit once (voxgi_addon/gi/radiance_cache.py face_paths,
 * exact_indirect.ray_paths): ray j of voxel face f is record i = f · rays + j, at texel
 * (i mod W, i div W) of the W-wide outputs. The faces: gbuffer_position (origin xyz, 1) and
 * gbuffer_normal (unit axis) at texel (f mod Wf, f div Wf), sample id f (face_points' row).
 * out_image    = (the ray's radiance without the cache rgb, 1 on a hit / 0 on a miss)
 * out_variance = (the hit's cache weight rgb, 0)       (bvh_shade.glsl ray_paths)
 * out_points   = (the hit point xyz, 0)
 * out_normals  = (the hit's shading normal xyz, 0)
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
  vec3 x, ns, weight;
  vec3 radiance = ray_paths(origin, d, id * uint(rays) + uint(j), seed, int(sampling.w),
                            world.w > 0.5, world.rgb, false, th, x, ns, weight);
  imageStore(out_image, texel, vec4(radiance, th < BVH_FAR ? 1.0 : 0.0));
  imageStore(out_variance, texel, vec4(weight, 0.0));
  imageStore(out_points, texel, vec4(x, 0.0));
  imageStore(out_normals, texel, vec4(ns, 0.0));
}

/* Exact AO and the raw one-bounce diffuse-indirect estimate per G-buffer pixel: the port of
 * voxgi_addon/indirect.indirect_and_ao (its module doc defines both), rays through the BVH.
 * out = (Diffuse Indirect rgb, Ambient Occlusion). Push constants:
 *   sampling = (seed, rays, ao_distance, strata side m of the hit's light samples)
 *   world    = rgb radiance of a miss
 * Sampler `materials`: (M + 1) × 2 texels, row 0 albedo, row 1 emission (last column: none). */

vec4 bvh_texel_normals(int k)
{
  return texelFetch(bvh_normals, ivec2(k & (BVH_WIDTH - 1), k >> BVH_WIDTH_LOG2), 0);
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  uint id = uint((size.y - 1 - px.y) * size.x + px.x);
  uint seed = uint(sampling.x);
  int rays = int(sampling.y);
  int last_material = textureSize(materials, 0).x - 1;
  vec3 origin = position.xyz + SURFACE_EPSILON * n;
  uint state = point_stream(id, RAY_STREAM, seed);
  vec3 t, b;
  perpendicular_basis(n, t, b);
  vec3 sum = vec3(0.0);
  float unoccluded = 0.0;
  for (int j = 0; j < rays; j++) {
    vec2 disk = concentric_disk(hammersley(state, j, rays));
    float z = sqrt(max(0.0, 1.0 - dot(disk, disk)));
    vec3 d = normalize(disk.x * t + disk.y * b + z * n);
    float th;
    int triangle, slot;
    vec2 uv;
    if (!bvh_closest_hit(origin, d, SHADOW_EPSILON, BVH_FAR, th, triangle, slot, uv)) {
      unoccluded += 1.0;
      sum += world.rgb;
      continue;
    }
    unoccluded += th >= sampling.z ? 1.0 : 0.0;
    vec3 x = origin + th * d;
    vec3 face = bvh_triangle_face_normal(slot);
    vec3 smooth_n = (1.0 - uv.x - uv.y) * bvh_texel_normals(3 * slot).xyz +
                    uv.x * bvh_texel_normals(3 * slot + 1).xyz +
                    uv.y * bvh_texel_normals(3 * slot + 2).xyz;
    float len = length(smooth_n);
    vec3 ns = len > 1e-12 ? smooth_n / len : face;
    ns *= dot(face, d) > 0.0 ? -1.0 : 1.0;
    int material = bvh_triangle_material(slot);
    material = (material >= 0 && material < last_material) ? material : last_material;
    vec3 albedo = texelFetch(materials, ivec2(material, 0), 0).rgb;
    vec3 emission = texelFetch(materials, ivec2(material, 1), 0).rgb;
    vec3 direct = diffuse_direct(x + ns * SURFACE_EPSILON, ns, id * uint(rays) + uint(j),
                                 seed + 1u, int(sampling.w));
    sum += albedo * direct + emission;
  }
  imageStore(out_image, px, vec4(sum / float(rays), unoccluded / float(rays)));
}

/* The final gather of the Accurate integrator at reduced resolution: the exact one-bounce
 * Diffuse Indirect estimate and AO, for the G-buffer pixel each low-resolution cell traces
 * (pixels.glsl traced_pixel), plus the variance of both means for the à-trous filter
 * (voxgi_addon/gi/exact_indirect.py indirect_and_ao(..., statistics=True) is the reference).
 * out_image = (Diffuse Indirect rgb, AO); out_variance = (var of the indirect luminance mean,
 * var of the AO mean, −the reach, 0): the reach is the harmonic mean of the rays' hit
 * distances (a miss counts as infinitely far; 0: no ray hit), the scale the light changes over
 * about the point, which bounds the filter's taps (denoise.glsl, denoise.py REACH). Push
 * constants:
 *   sampling = (seed, rays, ao_distance, strata side m of the hit's light samples)
 *   world    = rgb radiance of a miss, w: 1 = the hit's glossy lobe reflects the lights too
 *   grid     = (stride, full width, full height, 0)
 *   chunk    = (first ray, rays of this dispatch, 1 = add to partial_*, 1 = last dispatch)
 * The rays of a point are split over several dispatches (render/gpu_gather.py
 * rays_per_dispatch): llvmpipe stops every loop of an invocation after 65535 iterations in all
 * (docs/blender_facts.md "llvmpipe's loop limit"), which silently dropped rays past about the
 * 600th. Dispatches before the last write raw sums (rgb, unoccluded rays) and (Σ luminance²,
 * the point's geometric normal in octahedral coordinates, Σ 1 / hit distance); the last one
 * writes the outputs above.
 * out_hidden = (the world's rest hidden from the point, in Diffuse Direct's units: Σ over the
 * rays that a surface stops (or that dip below the triangle's plane) of the world's rest
 * radiance along them (bvh_lights.glsl world_rest_radiance; a map's sun left out with grid.w's
 * flag 4, where the pixels trace it apart) / rays, the share of such rays); before the last
 * dispatch (Σ, count). F12's pixel centres subtract it, filtered and upsampled, from the world's
 * unshadowed light (docs/gi_pipeline.md "The world's light at the gather points").  * Sampler `materials`: (M + 1) × 3 texels, row 0 base colour, row 1 emission, row 2 (metallic,
 * Specular IOR Level, roughness) (last column: none); `principled_lut`: principled.glsl's. */

/* The geometric normal of the triangle under the surface point `q` seen along unit `view`, on
 * the side of the shading normal `n` (voxgi_addon/gi/surface_lookup.py geometric_normals:
 * a ray from TERMINATOR_REACH in front of it to as far behind, the face trusted within 60° of
 * `n`); `n` where none is found or trusted. */
vec3 geometric_normal(vec3 q, vec3 view, vec3 n)
{
  int slot;
  vec2 uv;
  vec3 face;
  return surface_triangle(q, view, n, slot, uv, face) && dot(face, n) > TERMINATOR_TRUST ? face
                                                                                         : n;
}

/* A unit vector in octahedral coordinates (two floats) and back. */
vec2 octahedral(vec3 v)
{
  v /= abs(v.x) + abs(v.y) + abs(v.z);
  vec2 folded = (1.0 - abs(v.yx)) * vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0);
  return v.z >= 0.0 ? v.xy : folded;
}

vec3 from_octahedral(vec2 e)
{
  vec3 v = vec3(e, 1.0 - abs(e.x) - abs(e.y));
  if (v.z < 0.0) {
    v.xy = (1.0 - abs(v.yx)) * vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0);
  }
  return normalize(v);
}

void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  near_follow = true;
  vec3 position, n;
  vec4 ray;
  uint id;
  if (!gather_point(cell, position, n, ray, id)) {
    imageStore(out_hidden, cell, vec4(0.0));
    return;
  }
  bool sun_apart = (int(grid.w + 0.5) & 4) != 0;
  /* Cycles' diffuse BSDF draws its directions about the shading normal and drops those below
   * the triangle's own plane (bsdf_diffuse_sample): they carry no light here either (AO still
   * counts them). The first dispatch of a point finds the triangle (a short ray) and hands its
   * normal on in its partial variance's .yzw; the later ones read it there (a viewport slice
   * splits a point's rays over dozens of dispatches). */
  vec3 ng = chunk.z > 0.5 ? from_octahedral(texelFetch(partial_variance, cell, 0).yz) :
                            geometric_normal(position + VIEW_BACKOFF * ray.xyz, ray.xyz, n);
  uint seed = uint(sampling.x);
  int rays = int(sampling.y);
  vec3 origin = position + surface_offset(position, SURFACE_EPSILON) * n;
  uint state = point_stream(id, RAY_STREAM, seed);
  vec3 t, b;
  perpendicular_basis(n, t, b);
  const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);
  vec3 sum = vec3(0.0);
  float lum2 = 0.0;
  float unoccluded = 0.0;
  float nearness = 0.0; /* Σ 1 / the rays' hit distances (a miss: 0) */
  vec4 hidden = vec4(0.0); /* (Σ the world's rest along the hidden rays, their count) */
  if (chunk.z > 0.5) {
    vec4 partial = texelFetch(partial_image, cell, 0);
    sum = partial.rgb;
    unoccluded = partial.a;
    vec4 partial_var = texelFetch(partial_variance, cell, 0);
    lum2 = partial_var.x;
    nearness = partial_var.w;
    hidden = texelFetch(partial_hidden, cell, 0);
  }
  /* the receiver's closures, for the chance Cycles picked a ray glossily (receiver_glossy:
   * such a path keeps every diffuse bounce to come, one more of the cache at its hit) */
  vec3 v = -ray.xyz;
  vec3 base, params;
  receiver_material(ray.w, base, params);
  float cos_ni = dot(n, v);
  vec4 picks = closure_picks(base, params, cos_ni);
  bool picked = textureSize(radiance_cache, 0).x > 1 && /* (read only with a cache) */
                picks.z > PR_ROUGHNESS_SQ_THRESHOLD && cos_ni > 0.0 && picks.x > 0.0;
  int first_ray = int(chunk.x);
  int end_ray = min(rays, first_ray + int(chunk.y));
  /* the rays' paths as one stream (bvh_shade.glsl path_step): each step one bounce */
  int j = first_ray;
  bool tracing = false;
  Path path;
  vec3 d = n;
  for (int step = 0; step < (end_ray - first_ray) * (MAX_FOLLOWS + 1); step++) {
    if (!tracing) {
      if (j >= end_ray) {
        break;
      }
      near_normal = n; /* the receiver of the ray's near hits (bvh_shade.glsl) */
      vec2 disk = concentric_disk(hammersley(state, j, rays));
      float z = sqrt(max(0.0, 1.0 - dot(disk, disk)));
      d = normalize(disk.x * t + disk.y * b + z * n);
      receiver_glossy = picked ? glossy_pick_chance(n, v, d, picks) : 0.0;
      path = path_start(origin, d, id * uint(rays) + uint(j));
      j++;
      tracing = true;
    }
    if (path_step(path, seed, int(sampling.w), world.w > 0.5, world.rgb, false)) {
      tracing = false;
      vec3 radiance = dot(d, ng) > 0.0 ? path.total : vec3(0.0);
      unoccluded += path.th >= sampling.z ? 1.0 : 0.0;
      nearness += path.th < BVH_FAR ? 1.0 / max(path.th, NEAREST_HIT) : 0.0;
      if (path.th < BVH_FAR || dot(d, ng) <= 0.0) {
        hidden += vec4(world_rest_radiance(d, sun_apart), 1.0);
      }
      sum += radiance;
      float l = dot(radiance, LUMINANCE);
      lum2 += l * l;
    }
  }
  if (chunk.w < 0.5) {
    imageStore(out_image, cell, vec4(sum, unoccluded));
    imageStore(out_variance, cell, vec4(lum2, octahedral(ng), nearness));
    imageStore(out_hidden, cell, hidden);
    return;
  }
  float count = float(rays);
  vec3 mean = sum / count;
  float lum_mean = dot(mean, LUMINANCE);
  float lum_var = max(lum2 / count - lum_mean * lum_mean, 0.0) / max(count - 1.0, 1.0);
  /* AO is a share of rays: its variance from a share pulled half a ray towards 1/2, so a
   * cell whose rays all agree still admits neighbours within about one ray's worth. */
  float share = (unoccluded + 0.5) / (count + 1.0);
  float ao_var = share * (1.0 - share) / count;
  imageStore(out_image, cell, vec4(mean, unoccluded / count));
  float reach = nearness > 0.0 ? count / nearness : 0.0;
  imageStore(out_variance, cell, vec4(lum_var, ao_var, -reach, 0.0));
  imageStore(out_hidden, cell, hidden / count);
}

/* The glossy gather of the Accurate integrator at reduced resolution: exact one-bounce Glossy
 * Indirect (without the glossy colour) for the G-buffer pixel each low-resolution cell traces,
 * and the variance of its luminance mean (voxgi_addon/gi/exact_glossy.py glossy_indirect is the
 * reference and has the estimator: reflections of GGX visible-normal samples, weighted by the
 * Principled glossy BSDF × cos over their density). out_image = (Glossy Indirect rgb, 0);
 * out_variance = (variance, 0, 0, 0). Push constants as bvh_gather.glsl's, with
 * sampling.y = the glossy rays; the rays are split over dispatches the same way (chunk).
 * With grid.w = 1 the kernel gathers the world's Glossy Direct instead (exact_glossy.py
 * glossy_world_direct, the map's sun left out of a lobe that is not a mirror's), the same
 * outputs. */

void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  vec3 position, n;
  vec4 ray;
  uint id;
  if (!gather_point(cell, position, n, ray, id)) {
    return;
  }
  vec3 v = -ray.xyz;
  int last_material = textureSize(materials, 0).x - 1;
  vec3 base, params;
  receiver_material(ray.w, base, params);
  float rough = clamp(params.z, 0.0, 1.0);
  float alpha = rough * rough;
  float alpha2 = alpha * alpha;
  bool mirror = alpha2 <= PR_ROUGHNESS_SQ_THRESHOLD;
  float cos_ni = dot(n, v);
  vec3 colour = principled_glossy_color(base, params.x, params.y, rough, clamp(cos_ni, 0.0, 1.0));
  vec3 t, b;
  perpendicular_basis(n, t, b);
  vec3 v_local = normalize(vec3(dot(t, v), dot(b, v), max(cos_ni, 1e-4)));
  float pdf_scale = 4.0 * max(cos_ni, 1e-4) * (1.0 + pr_ggx_lambda(alpha2, max(cos_ni, 1e-4)));

  uint seed = uint(sampling.x);
  int rays = int(sampling.y);
  bool world_mode = mod(grid.w, 2.0) > 0.5; /* Glossy Direct of the world and the emitters */
  if (!world_mode && params.x >= 0.5) {
    rays *= METAL_RAY_FACTOR; /* exact_glossy.glossy_indirect: a metal's colour is all glossy */
  }
  vec3 origin = position + surface_offset(position, SURFACE_EPSILON) * n;
  uint state = point_stream(id, GLOSSY_STREAM, seed);
  uint world_state = point_stream(id, WORLD_GLOSSY_STREAM, seed);
  bool sky_on = world_on();
  /* a uniform world: the lobe's rays alone (the map's importance is uniform over the sphere,
   * half of it below the horizon: exact_glossy.glossy_world_direct) */
  bool uniform_sky = sky_on && world_uniform();
  bool emitting = emitter_header().w > 0.5;
  const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);
  vec3 sum = vec3(0.0);
  float lum2 = 0.0;
  if (chunk.z > 0.5) {
    sum = texelFetch(partial_image, cell, 0).rgb;
    vec4 partial = texelFetch(partial_variance, cell, 0);
    lum2 = partial.x;
  }
  bool reflects = cos_ni > 0.0 && dot(colour, vec3(1.0)) > 0.0;
  /* the closures' sample weights for the chance Cycles picked a direction glossily
   * (exact_glossy._Lobe.glossy_chance: their directional albedos) */
  vec4 picks = closure_picks(base, params, cos_ni);
  /* the map's sun (world_light.Sun): a lobe that is not a mirror's takes it at its pixels, as
   * a lamp (passes.map_sun_shine), so the world's gather leaves its pixels out */
  float sun_above = 1e30;
  if (world_mode && !mirror && sky_on) {
    ivec2 last = ivec2(0, textureSize(world_map, 0).y - 1);
    if (texelFetch(world_map, last + ivec2(1, 0), 0).w > 0.5) {
      sun_above = texelFetch(world_map, last + ivec2(2, 0), 0).x;
    }
  }
  int first_ray = int(chunk.x);
  int end_ray = min(rays, first_ray + int(chunk.y));
  for (int j = first_ray; j < end_ray && reflects; j++) {
    vec3 h = n;
    if (!mirror) {
      vec3 hl = vndf_half_vector(v_local, alpha, hammersley(state, j, rays));
      h = hl.x * t + hl.y * b + hl.z * n;
    }
    vec3 l = normalize(2.0 * dot(v, h) * h - v);
    vec3 weight = vec3(1.0); /* a mirror: the pass is the reflected radiance itself */
    float pdf = 0.0;
    if (!mirror) {
      pdf = lobe_pdf(n, v, l, alpha2, pdf_scale);
      weight = dot(l, n) > 0.0 && pdf > 0.0 ?
               principled_glossy_reflectance(base, params.x, params.y, rough, n, v, l) /
               max(pdf, 1e-30) / max(colour, vec3(1e-30)) : vec3(0.0);
    }
    vec3 value = vec3(0.0);
    if (world_mode) {
      /* Glossy Direct of the world and emitters (exact_glossy.glossy_world_direct): the lobe's
       * ray where it lands on an emitter or reaches the sky, then one ray by the map's
       * importance, balance heuristic for the sky */
      vec4 head = world_header();
      int wh = int(head.x);
      int ww = int(head.y);
      if (dot(weight, vec3(1.0)) > 0.0 && dot(l, n) > 0.0) {
        float th;
        int triangle, slot;
        vec2 uv;
        if (bvh_closest_hit(origin, l, 0.0, BVH_FAR, th, triangle, slot, uv)) {
          if (emitting && mirror) { /* a glossy lobe gets the emitters from
                                     * bvh_emitter_glossy.glsl */
            int hit_material = bvh_triangle_material(slot);
            hit_material = (hit_material >= 0 && hit_material < last_material) ? hit_material
                                                                               : last_material;
            value += hit_emission(hit_material, triangle, uv) * weight;
          }
        }
        else if (sky_on) {
          vec3 sky = world_radiance_at(world_pixel(l, wh, ww));
          float map_pdf = uniform_sky ? 0.0 : dot(sky, LUMA) / head.w;
          float share = mirror ? 1.0 : pdf / max(pdf + map_pdf, 1e-30);
          value += dot(sky, LUMA) <= sun_above ? sky * weight * share : vec3(0.0);
        }
      }
      if (!mirror && sky_on && !uniform_sky) {
        vec3 le = world_sample(hammersley(world_state, j, rays), wh, ww);
        vec3 sky = world_radiance_at(world_pixel(le, wh, ww));
        float map_pdf = dot(sky, LUMA) / head.w;
        if (dot(le, n) > 0.0 && map_pdf > 0.0 && dot(sky, LUMA) <= sun_above &&
            !bvh_any_hit(origin, le, BVH_FAR)) {
          float both = lobe_pdf(n, v, le, alpha2, pdf_scale) + map_pdf;
          value += sky * principled_glossy_reflectance(base, params.x, params.y, rough, n, v, le) /
                   max(both, 1e-30) / max(colour, vec3(1e-30));
        }
      }
      value = mix(vec3(0.0), value, greaterThan(colour, vec3(0.0)));
    }
    else if (dot(weight, vec3(1.0)) > 0.0) {
      float th;
      receiver_glossy = mirror ? 1.0 : glossy_pick_chance(n, v, l, picks);
      vec3 radiance = ray_radiance(origin, l, id * uint(rays) + uint(j), seed, int(sampling.w),
                                   world.w > 0.5, world.rgb, false, th);
      value = mix(vec3(0.0), weight * radiance, greaterThan(colour, vec3(0.0)));
    }
    sum += value;
    float lum = dot(value, LUMINANCE);
    lum2 += lum * lum;
  }
  if (chunk.w < 0.5) {
    imageStore(out_image, cell, vec4(sum, 0.0));
    imageStore(out_variance, cell, vec4(lum2, 0.0, 0.0, 0.0));
    return;
  }
  float count = float(rays);
  vec3 mean = sum / count;
  float lum_mean = dot(mean, LUMINANCE);
  float var = max(lum2 / count - lum_mean * lum_mean, 0.0) / max(count - 1.0, 1.0);
  imageStore(out_image, cell, vec4(mean, 0.0));
  imageStore(out_variance, cell, vec4(var, 0.0, 0.0, 0.0));
}

/* The glossy light the emissive triangles send toward the viewer per G-buffer pixel (Glossy
 * Color x their Glossy Direct): the port of voxgi_addon/gi/exact_glossy.py emitters_shine /
 * emitters_glossy. For each emitting triangle facing the point, the LTC integral of the GGX lobe
 * over it (ltc.glsl) x the Principled lobe's reflectance where the lobe meets it over the fitted
 * lobe's (full lobe for small triangles, Fresnel for those that fill it) x its radiance, summed,
 * x a white metal's glossy colour (the unshadowed light, emitter_glossy_unshadowed), x the
 * visible share of `rays` points drawn on the emitters by power (stream
 * EMITTER_GLOSSY_STREAM), each weighted by the luminance of L f |cos_l| / (r^2 p_area); 0 for
 * a mirror (its reflected ray sees the emitters in the glossy gather).
 * Samplers as bvh_direct.glsl's (centre_shine for its centre_unshadowed) plus materials,
 * principled_lut, gbuffer_base = (Base Color per texel, 1) where textured, ltc_table and
 * emitter_field. Push constants: sampling = (seed, rays, mode, field given).
 * The unshadowed light is a smooth field (docs/gi_pipeline.md "Where a preview's time goes"):
 * mode 2 writes it at the gather points, out = (the unshadowed light over this point's Glossy
 * Color, 0), no rays; the preview upsamples it (upsample.glsl UPSAMPLE_FIELD: emitter_field =
 * (that light, the angle the lobe turns across the taps, < 0 where none fits)). Modes 0 and 1,
 * given the field, take field x this point's Glossy Color where the field's angle is within
 * NEAR_STEP of the lobe's width (min(1, 2 alpha)) and evaluate the sum only elsewhere; the
 * visible share is always this point's own. out = (rgb, 1).
 * mode 1 (a sub-pixel pass over the edge pixels' list): centre_position, centre_normal,
 * centre_view hold the pixel centres' G-buffer at the same texels (aa_compact.glsl) and
 * centre_shine this kernel's value there; a texel whose pass sees the surface its centre sees
 * (same_surface.glsl) takes centre_shine, the others read the field at the pass's own point
 * (upsample.glsl UPSAMPLE_LIST) as mode 0 does. */

/* Σ over the emitting triangles facing p of the LTC integral × the lobe's reflectance ×
 * radiance, × white_colour (exact_glossy.emitters_glossy's unshadowed part; glossy_ltc.glsl
 * glossy_ltc_triangle); v above the horizon of n. Over the triangles the sums run over
 * (emitter_sums: a proxy where the emitters are many). */
vec3 emitter_glossy_unshadowed(vec3 p, vec3 n, vec3 v, GlossyLobe g, float rough,
                               vec3 white_colour)
{
  ivec2 rows = emitter_sums();
  vec3 unshadowed = vec3(0.0);
  LtcLobe lobe = ltc_lobe(n, v, rough);  /* the same for every triangle */
  if (!(g.white > 0.0)) {
    return unshadowed;  /* plain is 0 everywhere: so is the Fresnel ratio */
  }
  for (int k = rows.x; k < rows.x + rows.y; k++) {
    if (!emitter_facing(k, p)) {
      continue;
    }
    vec3 c0 = texelFetch(emitters, ivec2(0, k), 0).xyz;
    vec3 c1 = texelFetch(emitters, ivec2(1, k), 0).xyz;
    vec3 c2 = texelFetch(emitters, ivec2(2, k), 0).xyz;
    unshadowed += glossy_ltc_triangle(lobe, g, p, n, v, c0, c1, c2, white_colour) *
                  vec3(texelFetch(emitters, ivec2(0, k), 0).w,
                       texelFetch(emitters, ivec2(1, k), 0).w,
                       texelFetch(emitters, ivec2(2, k), 0).w);
  }
  return unshadowed * white_colour;
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  vec4 head = emitter_header();
  if (position.w < 0.5 || head.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  int mode = int(sampling.z + 0.5);
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec4 ray = texelFetch(gbuffer_view, px, 0);
  if (mode == 1 && same_surface(position, n, ray.w, px)) {
    imageStore(out_image, px, texelFetch(centre_shine, px, 0));
    return;
  }
  vec3 p = position.xyz + surface_offset(position.xyz, SURFACE_EPSILON) * n; /* off an emitter's own plane */
  vec3 v = -ray.xyz;
  int last_material = textureSize(materials, 0).x - 1;
  int material = int(ray.w + 0.5);
  material = (material >= 0 && material < last_material) ? material : last_material;
  vec4 texel = texelFetch(gbuffer_base, px, 0);  /* Base Color per texel (G-buffer) */
  vec3 base = texel.w > 0.5 ? texel.rgb : texelFetch(materials, ivec2(material, 0), 0).rgb;
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
  float rough = clamp(params.z, 0.0, 1.0);
  float alpha = rough * rough;
  float cos_ni = dot(n, v);
  if (alpha * alpha <= PR_ROUGHNESS_SQ_THRESHOLD || !(cos_ni > 0.0)) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  int count = int(head.x);
  vec3 white_colour = principled_glossy_color(vec3(1.0), 1.0, params.y, rough, clamp(cos_ni, 0.0, 1.0));
  vec3 colour = principled_glossy_color(base, params.x, params.y, rough, clamp(cos_ni, 0.0, 1.0));
  GlossyLobe g = glossy_lobe(base, params.x, params.y, rough, cos_ni);
  if (mode == 2) {  /* the field at a gather point: the light over the point's Glossy Color */
    vec3 light = emitter_glossy_unshadowed(p, n, v, g, rough, white_colour);
    imageStore(out_image, px, vec4(mix(vec3(0.0), light / max(colour, vec3(1e-30)),
                                       greaterThan(colour, vec3(0.0))), 0.0));
    return;
  }
  vec4 field = sampling.w > 0.5 ? texelFetch(emitter_field, px, 0) : vec4(-1.0);
  vec3 unshadowed = (field.w >= 0.0 && field.w <= NEAR_STEP * min(1.0, 2.0 * alpha)) ?
                    field.rgb * colour :
                    emitter_glossy_unshadowed(p, n, v, g, rough, white_colour);
  uint id = position.w > 1.5 ? uint(position.w) - 2u  /* a listed pixel: aa_compact.glsl */
                             : uint((size.y - 1 - px.y) * size.x + px.x);
  const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);
  int rays = int(sampling.y);
  uint state = point_stream(id, EMITTER_GLOSSY_STREAM, uint(sampling.x));
  vec3 origin = p;
  /* the visible share (exact_glossy._emitter_weights) */
  float drawn_sum = 0.0;
  float seen_sum = 0.0;
  for (int j = 0; j < rays; j++) {
    int t;
    vec3 target = emitter_sample(hammersley(state, j, rays), count, t);
    vec3 c0 = texelFetch(emitters, ivec2(0, t), 0).xyz;
    vec3 c1 = texelFetch(emitters, ivec2(1, t), 0).xyz;
    vec3 c2 = texelFetch(emitters, ivec2(2, t), 0).xyz;
    vec3 w = target - origin;
    float r2 = dot(w, w);
    float dist = sqrt(r2);
    vec3 d = w / max(dist, 1e-30);
    vec3 normal = cross(c1 - c0, c2 - c0);
    normal /= max(length(normal), 1e-30);
    float cos_l = dot(d, normal);
    vec3 glow = vec3(texelFetch(emitters, ivec2(0, t), 0).w, texelFetch(emitters, ivec2(1, t), 0).w,
                     texelFetch(emitters, ivec2(2, t), 0).w);
    if (dot(d, n) > 0.0 && abs(cos_l) > 0.0 && emitter_facing(t, origin)) {
      float emit_pdf = dot(glow, LUMA) / head.y * r2 / abs(cos_l);
      float ggx;
      vec3 factor = glossy_lobe_at(g, n, v, d, dot(d, n), ggx);  /* the lobe's reflectance */
      float drawn = dot(glow * (ggx * factor), LUMINANCE) / max(emit_pdf, 1e-30);
      drawn_sum += drawn;
      if (!bvh_any_hit(origin, d, dist)) {
        seen_sum += drawn;
      }
    }
  }
  float visible = drawn_sum > 0.0 ? seen_sum / drawn_sum : 1.0;
  imageStore(out_image, px, vec4(unshadowed * visible, 1.0));
}

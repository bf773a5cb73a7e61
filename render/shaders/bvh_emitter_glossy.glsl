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

/* What the Principled glossy lobe's reflectance (principled_glossy_reflectance) needs of a
 * point whatever the light's direction: its lobes' Fresnel parameters and energy terms (table
 * lookups that depend on the view cosine and roughness only) and the view's Smith Λ. The
 * emitters' sum evaluates the lobe toward every triangle of the point, and a white metal's
 * too: both computed once per point (glossy_lobe), then per direction the same arithmetic as
 * principled_glossy_reflectance's (glossy_lobe_at). */
struct GlossyLobe {
  float alpha2;
  float cos_ni;
  float lambda_i;
  float dielectric;  /* weight × darkening × 1/E of the dielectric lobe (0: none) */
  float f0;
  float eta;
  float f0_real;
  bool has_metal;
  vec3 metal;        /* metallic × 1/E × darkening of the metal lobe */
  vec3 m_f0;
  float white;       /* a white metal's 1/E × darkening (its Fresnel is 1) */
};

/* The lobe of Base Color base, metallic, Specular IOR Level and roughness rough (clamped to
 * [0, 1]) at view cosine cos_ni > 0. */
GlossyLobe glossy_lobe(vec3 base, float metallic, float level, float rough, float cos_ni)
{
  GlossyLobe g;
  base = max(base, vec3(0.0));
  metallic = clamp(metallic, 0.0, 1.0);
  float alpha = rough * rough;
  g.alpha2 = alpha * alpha;
  g.cos_ni = cos_ni;
  g.lambda_i = pr_ggx_lambda(g.alpha2, cos_ni);
  float scale, darkening, albedo;
  bool present = pr_dielectric(rough, cos_ni, level, g.f0, g.eta, scale, darkening, albedo);
  g.has_metal = metallic > PR_WEIGHT_CUTOFF;
  g.f0_real = pr_f0_from_ior(g.eta);
  g.dielectric = present ? (g.has_metal ? 1.0 - metallic : 1.0) * darkening * scale : 0.0;
  vec3 m_dark, m_albedo;
  float m_scale;
  g.metal = vec3(0.0);
  g.m_f0 = vec3(0.0);
  if (g.has_metal) {
    pr_metal(base, rough, cos_ni, g.m_f0, m_scale, m_dark, m_albedo);
    g.metal = metallic * m_scale * m_dark;
  }
  vec3 white_f0;
  pr_metal(vec3(1.0), rough, cos_ni, white_f0, m_scale, m_dark, m_albedo);
  g.white = m_scale * m_dark.x;
  return g;
}

/* principled_glossy_reflectance of the point's lobe toward `light` (cos_no = n·light > 0):
 * its GGX term (D G / (4 cos_ni)) in ggx and the Fresnel-weighted factor the lobe multiplies
 * it by (returned); a white metal's is ggx × g.white. */
vec3 glossy_lobe_at(GlossyLobe g, vec3 n, vec3 view, vec3 light, float cos_no, out float ggx)
{
  vec3 h = normalize(view + light);
  float cos_nh = dot(n, h);
  float cos_hi = dot(h, view);
  float c2 = min(cos_nh * cos_nh, 1.0);
  vec3 nxh = cross(n, h);
  float den = min(dot(nxh, nxh), 1.0) + g.alpha2 * c2;
  float d = g.alpha2 / (PR_PI * den * den);
  ggx = d / (4.0 * g.cos_ni * (1.0 + g.lambda_i + pr_ggx_lambda(g.alpha2, cos_no)));
  vec3 factor = vec3(0.0);
  if (g.dielectric != 0.0) {
    float s = clamp((pr_fresnel_dielectric(cos_hi, g.eta) - g.f0_real) / (1.0 - g.f0_real), 0.0,
                    1.0);
    factor += vec3(g.dielectric * (g.f0 + (1.0 - g.f0) * s));
  }
  if (g.has_metal) {
    float s1 = clamp(1.0 - cos_hi, 0.0, 1.0);
    float s5 = s1 * s1 * s1 * s1 * s1;
    factor += g.metal * clamp(g.m_f0 + (1.0 - g.m_f0) * s5, 0.0, 1.0);
  }
  return factor;
}

/* Σ over the emitting triangles facing p of the LTC integral × the lobe's reflectance ×
 * radiance, × white_colour (exact_glossy.emitters_glossy's unshadowed part); v above the
 * horizon of n. Per triangle: the lobe's reflectance `actual` = ggx × factor and a white
 * metal's `plain` = ggx × white (glossy_lobe_at), the fitted lobe `model` = the LTC's density ×
 * white_colour, and exact_glossy's blend (actual / model)^trust (actual / plain)^(1 − trust)
 * = factor × exp(trust log(ggx / model) − (1 − trust) log white): one logarithm of the
 * triangle's, not two per channel. */
vec3 emitter_glossy_unshadowed(vec3 p, vec3 n, vec3 v, GlossyLobe g, float rough,
                               vec3 white_colour, int count)
{
  vec3 unshadowed = vec3(0.0);
  LtcLobe lobe = ltc_lobe(n, v, rough);  /* the same for every triangle */
  if (!(g.white > 0.0)) {
    return unshadowed;  /* plain is 0 everywhere: so is the Fresnel ratio */
  }
  float log_white = log(g.white);
  vec3 log_colour = log(max(white_colour, vec3(1e-30)));
  for (int k = 0; k < count; k++) {
    if (!emitter_facing(k, p)) {
      continue;
    }
    vec3 c0 = texelFetch(emitters, ivec2(0, k), 0).xyz;
    vec3 c1 = texelFetch(emitters, ivec2(1, k), 0).xyz;
    vec3 c2 = texelFetch(emitters, ivec2(2, k), 0).xyz;
    vec3 towards;
    float shape = ltc_triangle_at(lobe, p, c0, c1, c2, towards);
    if (shape > 0.0) {
      towards = normalize(towards + max(HORIZON_LIFT - dot(towards, n), 0.0) * n);
      float cos_no = dot(n, towards);
      float ggx = 0.0;
      vec3 factor = cos_no > 0.0 ? glossy_lobe_at(g, n, v, towards, cos_no, ggx) : vec3(0.0);
      if (!(ggx > 0.0)) {
        continue;  /* actual and plain are 0 */
      }
      vec3 fresnel = factor / g.white;  /* actual / plain */
      float density = ltc_lobe_density_at(lobe, towards);
      if (density > 0.0) {
        /* the ratio trusted as far as the triangle is narrow (exact_glossy._narrow) */
        vec3 d0 = normalize(c0 - p), d1 = normalize(c1 - p), d2 = normalize(c2 - p);
        float spread = acos(clamp(min(min(dot(d0, d1), dot(d1, d2)), dot(d0, d2)), -1.0, 1.0));
        float trust = (1.0 - clamp(shape, 0.0, 1.0)) *
                      clamp(1.0 - spread / (0.5 * M_PI_F), 0.0, 1.0);
        vec3 blended = factor * exp(trust * (log(ggx / density) - log_colour) -
                                    (1.0 - trust) * log_white);
        bvec3 modelled = greaterThan(white_colour, vec3(0.0));
        fresnel = mix(fresnel, blended, modelled);
        fresnel = mix(vec3(0.0), fresnel, greaterThan(factor, vec3(0.0)));
      }
      unshadowed += shape * fresnel * vec3(texelFetch(emitters, ivec2(0, k), 0).w,
                                           texelFetch(emitters, ivec2(1, k), 0).w,
                                           texelFetch(emitters, ivec2(2, k), 0).w);
    }
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
  vec3 p = position.xyz + SURFACE_EPSILON * n; /* off an emitter's own plane */
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
    vec3 light = emitter_glossy_unshadowed(p, n, v, g, rough, white_colour, count);
    imageStore(out_image, px, vec4(mix(vec3(0.0), light / max(colour, vec3(1e-30)),
                                       greaterThan(colour, vec3(0.0))), 0.0));
    return;
  }
  vec4 field = sampling.w > 0.5 ? texelFetch(emitter_field, px, 0) : vec4(-1.0);
  vec3 unshadowed = (field.w >= 0.0 && field.w <= NEAR_STEP * min(1.0, 2.0 * alpha)) ?
                    field.rgb * colour :
                    emitter_glossy_unshadowed(p, n, v, g, rough, white_colour, count);
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

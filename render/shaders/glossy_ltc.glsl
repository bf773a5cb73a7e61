/* The Principled glossy lobe over polygons by LTC (ltc.glsl), with the Fresnel where the lobe
 * meets each triangle: the port of voxgi_addon/gi/exact_glossy.py _emitters_unshadowed, shared
 * by the emitters' glossy light (bvh_emitter_glossy.glsl) and a bounce hit's glossy lobe over an
 * area lamp (bvh_shade.glsl ray_paths, exact_glossy.area_glossy). Needs principled.glsl,
 * ltc.glsl (its ltc_table sampler and defines) and HORIZON_LIFT. */

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

/* One triangle's share of the lobe's light, without its radiance and the white metal's colour:
 * the LTC integral of the GGX lobe over it × the lobe's reflectance where the lobe meets it
 * over the fitted lobe's (exact_glossy._emitters_unshadowed): the reflectance `actual` = ggx ×
 * factor and a white metal's `plain` = ggx × white (glossy_lobe_at), the fitted lobe `model`
 * = the LTC's density × white_colour, and the blend (actual / model)^trust (actual /
 * plain)^(1 − trust) = factor × exp(trust log(ggx / model) − (1 − trust) log white): one
 * logarithm of the triangle's, not two per channel; the ratio trusted as far as the triangle
 * is narrow (exact_glossy._narrow). g.white > 0 (else every ratio is 0). */
vec3 glossy_ltc_triangle(LtcLobe lobe, GlossyLobe g, vec3 p, vec3 n, vec3 v, vec3 c0, vec3 c1,
                         vec3 c2, vec3 white_colour)
{
  vec3 towards;
  float shape = ltc_triangle_at(lobe, p, c0, c1, c2, towards);
  if (!(shape > 0.0)) {
    return vec3(0.0);
  }
  towards = normalize(towards + max(HORIZON_LIFT - dot(towards, n), 0.0) * n);
  float cos_no = dot(n, towards);
  float ggx = 0.0;
  vec3 factor = cos_no > 0.0 ? glossy_lobe_at(g, n, v, towards, cos_no, ggx) : vec3(0.0);
  if (!(ggx > 0.0)) {
    return vec3(0.0);  /* actual and plain are 0 */
  }
  vec3 fresnel = factor / g.white;  /* actual / plain */
  float density = ltc_lobe_density_at(lobe, towards);
  if (density > 0.0) {
    vec3 d0 = normalize(c0 - p), d1 = normalize(c1 - p), d2 = normalize(c2 - p);
    float spread = acos(clamp(min(min(dot(d0, d1), dot(d1, d2)), dot(d0, d2)), -1.0, 1.0));
    float trust = (1.0 - clamp(shape, 0.0, 1.0)) * clamp(1.0 - spread / (0.5 * M_PI_F), 0.0, 1.0);
    vec3 blended = factor * exp(trust * (log(ggx / density) - log(max(white_colour, vec3(1e-30)))) -
                                (1.0 - trust) * log(g.white));
    fresnel = mix(fresnel, blended, greaterThan(white_colour, vec3(0.0)));
    fresnel = mix(vec3(0.0), fresnel, greaterThan(factor, vec3(0.0)));
  }
  return shape * fresnel;
}

/* What the lobe over a polygon needs of a point whatever the polygon (area_glossy's and
 * glossy_direct.glsl disc_shine's): its GlossyLobe, LtcLobe and a white metal's glossy colour;
 * false for a mirror, a view at or below the horizon, or a lobe that reflects nothing. */
bool polygon_lobe(vec3 n, vec3 v, vec3 base, vec3 params, out GlossyLobe g, out LtcLobe lobe,
                  out vec3 white_colour)
{
  float rough = clamp(params.z, 0.0, 1.0);
  float alpha = rough * rough;
  float cos_ni = dot(n, v);
  if (alpha * alpha <= PR_ROUGHNESS_SQ_THRESHOLD || !(cos_ni > 0.0)) {
    return false;
  }
  g = glossy_lobe(base, params.x, params.y, rough, cos_ni);
  if (!(g.white > 0.0)) {
    return false;
  }
  white_colour = principled_glossy_color(vec3(1.0), 1.0, params.y, rough, clamp(cos_ni, 0.0, 1.0));
  lobe = ltc_lobe(n, v, rough);
  return true;
}

/* The unshadowed glossy light area lamp `light` (its outline's `count` corners, lights texels
 * 8…; radiance × colour) sends toward v off a surface at p with unit normal n (v above its
 * horizon) of Base Color base, (metallic, Specular IOR Level, roughness) params: the lobe over
 * the outline's fan of triangles (exact_glossy.area_glossy); 0 for a mirror. */
vec3 area_glossy(int light, int count, vec3 p, vec3 n, vec3 v, vec3 base, vec3 params)
{
  GlossyLobe g;
  LtcLobe lobe;
  vec3 white_colour;
  if (!polygon_lobe(n, v, base, params, g, lobe, white_colour)) {
    return vec3(0.0);
  }
  vec3 c0 = light_texel(light, 8).xyz;
  vec3 sum = vec3(0.0);
  for (int k = 1; k + 1 < count; k++) {
    sum += glossy_ltc_triangle(lobe, g, p, n, v, c0, light_texel(light, 8 + k).xyz,
                               light_texel(light, 9 + k).xyz, white_colour);
  }
  return sum * white_colour * light_texel(light, 6).y * light_texel(light, 1).rgb;
}

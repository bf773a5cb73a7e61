/* Cycles 5.0's Principled BSDF for opaque dielectrics and metals: a port of
 * voxgi_addon/gi/principled.py (docs/gi_pipeline.md "Principled materials"); read that module's
 * doc for the model. Needs the 2D sampler `principled_lut` (render/gpu_principled.py
 * lut_texture, red channel) and the defines of gpu_principled.DEFINES (its rows); IOR is
 * PRINCIPLED_IOR (the node's default 1.5).
 *
 * LUT rows (32 texels wide): [PR_ROW_E, +32) ggx_E[mu][rough]; PR_ROW_EAVG ggx_Eavg[rough];
 * [PR_ROW_IOR_S, +256) ior_s[z][mu][rough] (16 wide, row = z * 16 + mu);
 * [PR_ROW_METAL_S, +16) metal_s[mu][rough] (16 wide). */

#ifndef PRINCIPLED_IOR
#define PRINCIPLED_IOR 1.5
#endif
#define PR_PI 3.14159265358979
#define PR_ROUGHNESS_SQ_THRESHOLD 2e-10
#define PR_WEIGHT_CUTOFF 1e-5

/* Cycles' lookup_table_read along one row: grid points i / (n - 1), x clamped to [0, 1]. */
float pr_lut_row(int row, int n, float x)
{
  float f = clamp(x, 0.0, 1.0) * float(n - 1);
  int i = min(int(f), n - 1);
  int j = min(i + 1, n - 1);
  float t = f - float(i);
  float a = texelFetch(principled_lut, ivec2(i, row), 0).r;
  float b = texelFetch(principled_lut, ivec2(j, row), 0).r;
  return (1.0 - t) * a + t * b;
}

/* lookup_table_read_2D: rows row0 .. row0 + ny - 1 indexed by y. */
float pr_lut_2d(int row0, int nx, int ny, float x, float y)
{
  float f = clamp(y, 0.0, 1.0) * float(ny - 1);
  int i = min(int(f), ny - 1);
  int j = min(i + 1, ny - 1);
  float t = f - float(i);
  return (1.0 - t) * pr_lut_row(row0 + i, nx, x) + t * pr_lut_row(row0 + j, nx, x);
}

/* lookup_table_read_3D of the 16^3 ior_s table. */
float pr_lut_ior_s(float rough, float mu, float z)
{
  float f = clamp(z, 0.0, 1.0) * 15.0;
  int i = min(int(f), 15);
  int j = min(i + 1, 15);
  float t = f - float(i);
  return (1.0 - t) * pr_lut_2d(PR_ROW_IOR_S + 16 * i, 16, 16, rough, mu) +
         t * pr_lut_2d(PR_ROW_IOR_S + 16 * j, 16, 16, rough, mu);
}

float pr_f0_from_ior(float ior)
{
  float r = (ior - 1.0) / (ior + 1.0);
  return r * r;
}

float pr_ior_from_f0(float f0)
{
  float r = sqrt(clamp(f0, 0.0, 0.99));
  return (1.0 + r) / (1.0 - r);
}

/* Cycles' unpolarised dielectric Fresnel (1 on total internal reflection). */
float pr_fresnel_dielectric(float cos_i, float eta)
{
  cos_i = abs(cos_i);
  float g = eta * eta - (1.0 - cos_i * cos_i);
  if (g <= 0.0) {
    return 1.0;
  }
  float cos_t = -sqrt(g) / eta;
  float rs = (cos_i + eta * cos_t) / (cos_i - eta * cos_t);
  float rp = (cos_t + eta * cos_i) / (eta * cos_i - cos_t);
  return 0.5 * (rs * rs + rp * rp);
}

float pr_fresnel_dielectric_fss(float eta)
{
  if (eta < 1.0) {
    return 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607));
  }
  return (eta - 1.0) / (4.08567 + 1.00071 * eta);
}

/* F0 and eta of the dielectric lobe for a Specular IOR Level; eta == 1: no lobe. */
void pr_specular_f0_eta(float level, out float f0, out float eta)
{
  float ior = max(PRINCIPLED_IOR, 1e-5);
  f0 = pr_f0_from_ior(ior);
  eta = ior;
  level = max(level, 0.0);
  if (level != 0.5) {
    f0 *= 2.0 * level;
    eta = pr_ior_from_f0(f0);
    if (ior < 1.0) {
      eta = 1.0 / eta;
    }
  }
  f0 = clamp(f0, 0.0, 1.0);
}

/* Kulla-Conty compensation of a GGX lobe with mean Fresnel fss: the energy scale 1/E and the
 * weight factor E + F_ms (1 - E) (Cycles' darkening). */
void pr_energy(float rough, float mu, vec3 fss, out float scale, out vec3 darkening)
{
  float e = pr_lut_2d(PR_ROW_E, 32, 32, rough, mu);
  float e_avg = pr_lut_row(PR_ROW_EAVG, 32, rough);
  float missing = (1.0 - e) / e;
  vec3 fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg));
  scale = 1.0 / e;
  darkening = (1.0 + fms * missing) * e;
  darkening = mix(darkening, vec3(1.0), vec3(equal(fss, vec3(1.0))));
}

/* The dielectric lobe at view cosine mu: present?, F0, eta, 1/E, darkening, albedo estimate. */
bool pr_dielectric(float rough, float mu, float level, out float f0, out float eta,
                   out float scale, out float darkening, out float albedo)
{
  pr_specular_f0_eta(level, f0, eta);
  bool present = eta != 1.0;
  if (!present) {
    eta = 1.5;
  }
  float f0_real = pr_f0_from_ior(eta);
  float s_avg = clamp((pr_fresnel_dielectric_fss(eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0);
  float fss = f0 + (1.0 - f0) * s_avg;
  vec3 dark;
  pr_energy(rough, mu, vec3(fss), scale, dark);
  darkening = dark.x;
  float z = sqrt(abs((eta - 1.0) / (eta + 1.0)));
  float s = pr_lut_ior_s(rough, mu, z);
  albedo = darkening * (f0 + (1.0 - f0) * s);
  return present;
}

/* The metal lobe (F82 with a white tint = Schlick): F0, 1/E, darkening, albedo estimate. */
void pr_metal(vec3 base, float rough, float mu, out vec3 f0, out float scale, out vec3 darkening,
              out vec3 albedo)
{
  f0 = clamp(base, 0.0, 1.0);
  vec3 fss = f0 + (1.0 - f0) / 21.0;
  pr_energy(rough, mu, fss, scale, darkening);
  float s = pr_lut_2d(PR_ROW_METAL_S, 16, 16, rough, mu);
  albedo = darkening * (f0 + (1.0 - f0) * s);
}

/* Cycles' Diffuse Color pass for a view cosine mu = dot(normal, to viewer). */
vec3 principled_diffuse_weight(vec3 base, float metallic, float level, float roughness, float mu)
{
  base = max(base, vec3(0.0));
  metallic = clamp(metallic, 0.0, 1.0);
  float rough = clamp(roughness, 0.0, 1.0);
  float f0, eta, scale, darkening, albedo;
  bool present = pr_dielectric(rough, mu, level, f0, eta, scale, darkening, albedo);
  float layer = present ? clamp(1.0 - albedo, 0.0, 1.0) : 1.0;
  float weight = metallic > PR_WEIGHT_CUTOFF ? 1.0 - metallic : 1.0;
  return base * (weight * layer);
}

/* Cycles' Glossy Color pass. */
vec3 principled_glossy_color(vec3 base, float metallic, float level, float roughness, float mu)
{
  base = max(base, vec3(0.0));
  metallic = clamp(metallic, 0.0, 1.0);
  float rough = clamp(roughness, 0.0, 1.0);
  float f0, eta, scale, darkening, albedo;
  bool present = pr_dielectric(rough, mu, level, f0, eta, scale, darkening, albedo);
  bool has_metal = metallic > PR_WEIGHT_CUTOFF;
  vec3 color = vec3(present ? (has_metal ? 1.0 - metallic : 1.0) * albedo : 0.0);
  if (has_metal) {
    vec3 m_f0, m_dark, m_albedo;
    float m_scale;
    pr_metal(base, rough, mu, m_f0, m_scale, m_dark, m_albedo);
    color += metallic * m_albedo;
  }
  return color;
}

float pr_ggx_lambda(float alpha2, float cos_n)
{
  float tan2 = max(1.0 / (cos_n * cos_n) - 1.0, 0.0);
  return 0.5 * (sqrt(1.0 + alpha2 * tan2) - 1.0);
}

/* Glossy BSDF x cos(normal, light) (Cycles' eval): a sun of strength S adds S x this to the
 * glossy radiance toward `view`. n, view, light: unit vectors away from the surface. */
vec3 principled_glossy_reflectance(vec3 base, float metallic, float level, float roughness,
                                   vec3 n, vec3 view, vec3 light)
{
  base = max(base, vec3(0.0));
  metallic = clamp(metallic, 0.0, 1.0);
  float rough = clamp(roughness, 0.0, 1.0);
  float alpha = rough * rough;
  float alpha2 = alpha * alpha;
  float cos_ni = dot(n, view);
  float cos_no = dot(n, light);
  if (cos_ni <= 0.0 || cos_no <= 0.0 || alpha2 <= PR_ROUGHNESS_SQ_THRESHOLD) {
    return vec3(0.0);
  }
  vec3 h = normalize(view + light);
  float cos_nh = dot(n, h);
  float cos_hi = dot(h, view);
  float c2 = min(cos_nh * cos_nh, 1.0);
  /* 1 − cos² as |n × h|²: near a mirror's peak 1 − cos² keeps few float32 digits. */
  vec3 nxh = cross(n, h);
  float den = min(dot(nxh, nxh), 1.0) + alpha2 * c2;
  float d = alpha2 / (PR_PI * den * den);
  float ggx = d / (4.0 * cos_ni * (1.0 + pr_ggx_lambda(alpha2, cos_ni) +
                                      pr_ggx_lambda(alpha2, cos_no)));

  float f0, eta, scale, darkening, albedo;
  bool present = pr_dielectric(rough, cos_ni, level, f0, eta, scale, darkening, albedo);
  bool has_metal = metallic > PR_WEIGHT_CUTOFF;
  vec3 result = vec3(0.0);
  if (present) {
    float f0_real = pr_f0_from_ior(eta);
    float s = clamp((pr_fresnel_dielectric(cos_hi, eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0);
    float weight = has_metal ? 1.0 - metallic : 1.0;
    result += vec3(weight * darkening * scale * (f0 + (1.0 - f0) * s) * ggx);
  }
  if (has_metal) {
    vec3 m_f0, m_dark, m_albedo;
    float m_scale;
    pr_metal(base, rough, cos_ni, m_f0, m_scale, m_dark, m_albedo);
    float s1 = clamp(1.0 - cos_hi, 0.0, 1.0);
    float s5 = s1 * s1 * s1 * s1 * s1;
    vec3 fresnel = clamp(m_f0 + (1.0 - m_f0) * s5, 0.0, 1.0);
    result += metallic * ggx * m_scale * m_dark * fresnel;
  }
  return result;
}

/* Radiance toward `view` from a point lit by a light in direction `light` that gives
 * `irradiance` on a plane facing it (0 when shadowed): diffuse + glossy. The shading of a bounce
 * hit, `view` pointing back toward the receiver. */
vec3 principled_outgoing_radiance(vec3 base, float metallic, float level, float roughness,
                                  vec3 n, vec3 view, vec3 light, vec3 irradiance)
{
  float mu = dot(n, view);
  if (mu <= 0.0) {
    return vec3(0.0);
  }
  vec3 diffuse = principled_diffuse_weight(base, metallic, level, roughness, mu) *
                 (max(dot(n, light), 0.0) / PR_PI);
  return irradiance *
         (diffuse + principled_glossy_reflectance(base, metallic, level, roughness, n, view, light));
}

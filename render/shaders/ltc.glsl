/* Linearly Transformed Cosines for the Principled GGX lobe: a port of voxgi_addon/gi/ltc.py
 * (docs/gi_pipeline.md "LTC: the glossy lobe over polygons"; read that module's doc for the
 * model). ltc_triangle(p, n, v, roughness, c0, c1, c2) = the integral over the triangle (world
 * corners, either orientation, clipped to the point's horizon) of the normalised GGX lobe
 * rho (f cos / its hemisphere integral; no Fresnel) of the point p with unit normal n, unit
 * direction to the viewer v and Principled roughness; 0 when v is at or below the horizon.
 *
 * Needs the 2D sampler `ltc_table` (render/gpu_ltc.py ltc_texture: RGBA32F, one texel per
 * cell = (a, b, c, d) of M^-1 = [[a, 0, b], [0, c, 0], [d, 0, 1]], x = view axis
 * sqrt(1 - cos theta_v), y = roughness, both uniform on [0, 1]) and the defines of
 * gpu_ltc.DEFINES (LTC_ROUGH_SIZE, LTC_VIEW_SIZE, LTC_ROUGH_MIN: the roughness the r = 0 row
 * was fitted at). */

#define LTC_PI 3.14159265358979

/* The table's view coordinate sqrt(1 - cos theta_v) from the view's tangential part
 * |v - n (n.v)| = sin theta_v: sqrt(sin^2 / (1 + cos)). Near normal incidence a float's cos
 * loses theta (1 - cos rounds by 6e-8: theta by ~3e-4, which moves a narrow lobe's highlight). */
float ltc_view_x(vec3 n, vec3 v)
{
  float cos_view = dot(n, v);
  vec3 tangential = v - n * cos_view;
  return sqrt(clamp(dot(tangential, tangential) / max(1.0 + cos_view, 1e-6), 0.0, 1.0));
}

/* (phi, log s_x, log s_y, kappa) of a cell's (a, b, c, d) (ltc.py _params). */
vec4 ltc_params(vec4 m)
{
  float phi = atan(-m.y, m.x);
  float c = cos(phi);
  float s = sin(phi);
  float kappa = (s - m.w * c) / (c + m.w * s);
  float e = c + kappa * s;
  return vec4(phi, log(c / (m.x * e)), log(1.0 / (m.z * e)), kappa);
}

/* (a, b, c, d) of parameters (ltc.py _abcd). */
vec4 ltc_abcd(vec4 q)
{
  float c = cos(q.x);
  float s = sin(q.x);
  float e = c + q.w * s;
  float sx = exp(q.y);
  float sy = exp(q.z);
  return vec4(c / (sx * e), -s / (sx * e), 1.0 / (sy * e), (s - q.w * c) / e);
}

/* M^-1 = (a, b, c, d) at roughness and view_x = sqrt(1 - cos theta_v), clamped: the four cells
 * blended in their parameters, linear in view_x and in log(roughness) (ltc.py _interp). */
vec4 ltc_inverse_x(float roughness, float view_x)
{
  float r = clamp(roughness, 0.0, 1.0);
  float fv = clamp(view_x, 0.0, 1.0) * float(LTC_VIEW_SIZE - 1);
  int i = min(int(r * float(LTC_ROUGH_SIZE - 1)), LTC_ROUGH_SIZE - 2);
  int j = min(int(fv), LTC_VIEW_SIZE - 2);
  float t = fv - float(j);
  float log0 = log(max(float(i) / float(LTC_ROUGH_SIZE - 1), LTC_ROUGH_MIN));
  float log1 = log(max(float(i + 1) / float(LTC_ROUGH_SIZE - 1), LTC_ROUGH_MIN));
  float s = clamp((log(max(r, LTC_ROUGH_MIN)) - log0) / (log1 - log0), 0.0, 1.0);
  vec4 q00 = ltc_params(texelFetch(ltc_table, ivec2(j, i), 0));
  vec4 q01 = ltc_params(texelFetch(ltc_table, ivec2(j + 1, i), 0));
  vec4 q10 = ltc_params(texelFetch(ltc_table, ivec2(j, i + 1), 0));
  vec4 q11 = ltc_params(texelFetch(ltc_table, ivec2(j + 1, i + 1), 0));
  return ltc_abcd((1.0 - s) * ((1.0 - t) * q00 + t * q01) + s * ((1.0 - t) * q10 + t * q11));
}

vec4 ltc_inverse(float roughness, float cos_view)
{
  return ltc_inverse_x(roughness, sqrt(clamp(1.0 - cos_view, 0.0, 1.0)));
}

vec3 ltc_apply(vec4 m, vec3 w)
{
  return vec3(m.x * w.x + m.y * w.z, m.z * w.y, m.w * w.x + w.z);
}

/* Clamped cosine of the hemisphere under M^-1: (1 + sign(a - b d) a / sqrt(a^2 + d^2)) / 2. */
float ltc_hemisphere_norm(vec4 m)
{
  float s = (m.x - m.y * m.w) >= 0.0 ? 1.0 : -1.0;
  return 0.5 * (1.0 + s * m.x / sqrt(m.x * m.x + m.w * m.w));
}

/* One edge (x, y) of a polygon in the local frame: its term of the edge integral under M^-1
 * (θ × the unit normal of the great circle through the transformed corners) added to total.
 * The normal is taken as M^-1 x cross M^-1 y = cof(M^-1) (x cross y), cof = [[c, 0, -c d],
 * [0, a - b d, 0], [-b c, 0, a c]], from the unstretched corners (a narrow lobe's M^-1
 * stretches the polygon until its corners are nearly opposite, where a cross of the stretched
 * corners would cancel). */
void ltc_edge(vec3 x, vec3 y, vec4 m, inout vec3 total)
{
  vec3 g = cross(x, y);
  vec3 c = vec3(m.z * (g.x - m.w * g.z), (m.x - m.y * m.w) * g.y, m.z * (m.x * g.z - m.y * g.x));
  float s = length(c);
  if (s > 0.0) {
    total += atan(s, dot(ltc_apply(m, x), ltc_apply(m, y))) * c / s;
  }
}

/* The piece of a polygon's edge (x, y) on the side dot(plane, ·) >= 0 of a plane through the
 * origin (Sutherland-Hodgman's points: the crossing a + t (b - a), t = h_a / (h_a - h_b)):
 * returns whether any is left, in (x, y); where the edge leaves the side, its crossing is the
 * polygon's exit (`exit`, has_exit), where it enters, its entry. */
bool ltc_clip_edge(inout vec3 x, inout vec3 y, vec3 plane, inout vec3 exit, inout bool has_exit,
                   inout vec3 entry, inout bool has_entry)
{
  float hx = dot(plane, x);
  float hy = dot(plane, y);
  bool in_x = hx >= 0.0;
  bool in_y = hy >= 0.0;
  if (in_x != in_y) {
    float denom = hx - hy;
    float t = denom != 0.0 ? hx / denom : 0.0;
    vec3 cut = x + t * (y - x);
    if (in_x) {
      exit = cut;
      has_exit = true;
      y = cut;
    }
    else {
      entry = cut;
      has_entry = true;
      x = cut;
    }
  }
  return in_x || in_y;
}

/* An edge (x, y) of the polygon clipped to the surface's horizon: its piece above the
 * cosine's plane (`plane`) into the edge integral, its crossings of that plane recorded. */
void ltc_second_clip(vec3 x, vec3 y, vec3 plane, vec4 m, inout vec3 total, inout vec3 exit,
                     inout bool has_exit, inout vec3 entry, inout bool has_entry)
{
  if (ltc_clip_edge(x, y, plane, exit, has_exit, entry, has_entry)) {
    ltc_edge(x, y, m, total);
  }
}

/* The edge integral under M^-1 of the triangle (a, b, c) in the local frame clipped to the
 * surface's horizon (z >= 0) and then to the cosine's (the local plane d x + z >= 0), as
 * Sutherland-Hodgman would clip it, without a polygon in an array (a local array indexed by
 * a running count is slow to index on llvmpipe): each edge's piece inside both, the chord
 * of the first clip from its exit to its entry clipped by the second, and the chord of the
 * second (from its exit to its entry over the edges of the first's polygon). Returns the sum
 * of θ × the great circles' normals (ltc_edge). */
vec3 ltc_clipped_triangle(vec3 a, vec3 b, vec3 c, vec4 m)
{
  vec3 horizon = vec3(0.0, 0.0, 1.0);
  vec3 cosine = vec3(m.w, 0.0, 1.0);
  vec3 total = vec3(0.0);
  vec3 exit1 = vec3(0.0), entry1 = vec3(0.0), exit2 = vec3(0.0), entry2 = vec3(0.0);
  bool out1 = false, in1 = false, out2 = false, in2 = false;
  vec3 x = a, y = b;
  if (ltc_clip_edge(x, y, horizon, exit1, out1, entry1, in1)) {
    ltc_second_clip(x, y, cosine, m, total, exit2, out2, entry2, in2);
  }
  x = b;
  y = c;
  if (ltc_clip_edge(x, y, horizon, exit1, out1, entry1, in1)) {
    ltc_second_clip(x, y, cosine, m, total, exit2, out2, entry2, in2);
  }
  x = c;
  y = a;
  if (ltc_clip_edge(x, y, horizon, exit1, out1, entry1, in1)) {
    ltc_second_clip(x, y, cosine, m, total, exit2, out2, entry2, in2);
  }
  if (out1 && in1) {
    ltc_second_clip(exit1, entry1, cosine, m, total, exit2, out2, entry2, in2);
  }
  if (out2 && in2) {
    ltc_edge(exit2, entry2, m, total);
  }
  return total;
}

/* Rows (t, b, n) of the local frame: t toward the view (ltc.py local_frame). */
mat3 ltc_frame(vec3 n, vec3 v)
{
  vec3 t = v - n * dot(n, v);
  float len = length(t);
  if (len > 1e-6) {
    t /= len;
  }
  else {
    vec3 an = abs(n);
    vec3 axis = (an.x <= an.y && an.x <= an.z) ? vec3(1.0, 0.0, 0.0) :
                (an.y <= an.z ? vec3(0.0, 1.0, 0.0) : vec3(0.0, 0.0, 1.0));
    t = normalize(axis - n * dot(n, axis));
  }
  /* columns t, b, n: transpose(frame) * x = (t.x, b.x, n.x) */
  return transpose(mat3(t, cross(n, t), n));
}

/* What ltc_triangle_at and ltc_lobe_density_at need of a point's lobe, whatever the triangle:
 * its local frame, M^-1 (a table lookup through eight transcendental functions), the
 * hemisphere's norm and M. Computed once per point, not per triangle (the emitters' loops of
 * bvh_emitter_glossy.glsl; the same arithmetic, so the same values). */
struct LtcLobe {
  mat3 to_local;
  vec4 m;
  float norm;
  mat3 back;  /* M = inverse of M^-1 = [[a, 0, b], [0, c, 0], [d, 0, 1]] */
};

/* The lobe of the point with unit normal n, unit direction to the viewer v (above its
 * horizon) and Principled roughness. */
LtcLobe ltc_lobe(vec3 n, vec3 v, float roughness)
{
  LtcLobe lobe;
  lobe.to_local = ltc_frame(n, v);
  lobe.m = ltc_inverse_x(roughness, ltc_view_x(n, v));
  lobe.norm = ltc_hemisphere_norm(lobe.m);
  lobe.back = inverse(mat3(lobe.m.x, 0.0, lobe.m.w, 0.0, lobe.m.z, 0.0, lobe.m.y, 0.0, 1.0));
  return lobe;
}

/* ltc_lobe_density of a point's LtcLobe at the world unit direction w. */
float ltc_lobe_density_at(LtcLobe lobe, vec3 w)
{
  vec3 local = lobe.to_local * w;
  if (!(local.z > 0.0)) {
    return 0.0;
  }
  vec4 m = lobe.m;
  vec3 wo = ltc_apply(m, local);
  float len = length(wo);
  float det = abs(m.z * (m.x - m.y * m.w));
  return max(wo.z / len, 0.0) / LTC_PI * det / (len * len * len) / lobe.norm;
}

/* rho(w) of the fitted lobe (ltc.py ltc_lobe_density): the LTC's density over its hemisphere
 * integral at the world unit direction w; 0 below the horizon or where v is. */
float ltc_lobe_density(vec3 n, vec3 v, float roughness, vec3 w)
{
  if (!(dot(n, v) > 0.0)) {
    return 0.0;
  }
  return ltc_lobe_density_at(ltc_lobe(n, v, roughness), w);
}

/* ltc_triangle_towards of a point p whose LtcLobe is given. */
float ltc_triangle_at(LtcLobe lobe, vec3 p, vec3 c0, vec3 c1, vec3 c2, out vec3 towards)
{
  towards = transpose(lobe.to_local)[2];  /* n */
  vec4 m = lobe.m;
  vec3 total = ltc_clipped_triangle(lobe.to_local * (c0 - p), lobe.to_local * (c1 - p),
                                    lobe.to_local * (c2 - p), m);
  /* the polygon's mean direction in the cosine's space (ltc.py _clamped_cosine_integral) */
  vec3 mean = (total.z < 0.0 ? -total : total) / (2.0 * LTC_PI);
  float value = abs(total.z) / (2.0 * LTC_PI) / lobe.norm;
  vec3 local = lobe.back * mean;
  vec3 world = transpose(lobe.to_local) * local;
  if (value > 0.0 && dot(world, world) > 0.0) {
    towards = normalize(world);
  }
  return value;
}

/* ltc_triangle, and in `towards` the world unit direction where the lobe meets the triangle:
 * the clipped polygon's mean direction in the cosine's space carried back by M (ltc.py
 * ltc_polygon_integral's directions); n where the integral is 0. */
float ltc_triangle_towards(vec3 p, vec3 n, vec3 v, float roughness, vec3 c0, vec3 c1, vec3 c2,
                           out vec3 towards)
{
  towards = n;
  float cos_view = dot(n, v);
  if (!(cos_view > 0.0)) {
    return 0.0;
  }
  return ltc_triangle_at(ltc_lobe(n, v, roughness), p, c0, c1, c2, towards);
}

float ltc_triangle(vec3 p, vec3 n, vec3 v, float roughness, vec3 c0, vec3 c1, vec3 c2)
{
  vec3 towards;
  return ltc_triangle_towards(p, n, v, roughness, c0, c1, c2, towards);
}

#ifdef LTC_TEST_KERNEL
/* Test kernel (render/gpu_ltc.py evaluate): one point and triangle per texel, in_p = (p,
 * roughness), in_n = (n, -), in_v = (v, -), in_c0 / in_c1 / in_c2 = (corner, -);
 * out_image = (ltc_triangle, -, -, -). */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 p = texelFetch(in_p, px, 0);
  float value = ltc_triangle(p.xyz, texelFetch(in_n, px, 0).xyz, texelFetch(in_v, px, 0).xyz, p.w,
                             texelFetch(in_c0, px, 0).xyz, texelFetch(in_c1, px, 0).xyz,
                             texelFetch(in_c2, px, 0).xyz);
  imageStore(out_image, px, vec4(value, 0.0, 0.0, 1.0));
}
#endif

/* Diffuse Direct (irradiance / π, no albedo) of every light at a surface point, with shadow
 * rays through the BVH: a port of voxgi_addon/direct_light.diffuse_direct (its module doc has
 * the light models) with the hashed strata of sampling.hashed_square, so that
 * diffuse_direct(..., sample_ids=ids, seed=seed) draws the same samples.
 * Sampler `lights`: voxgi_addon/light_table.py, one row per light (LIGHT_TEXELS wide); a row
 * of type < 0 is padding. Needs bvh_common.glsl. */

#define NORMAL_OFFSET 1e-5 /* direct_light._NORMAL_OFFSET: shadow rays start off the surface */

vec4 light_texel(int light, int k)
{
  return texelFetch(lights, ivec2(k, light), 0);
}

/* Unoccluded share of the ray from `origin` to `target`: 1 or 0. */
float visible_to(vec3 origin, vec3 target)
{
  vec3 ray = target - origin;
  float len = length(ray);
  return bvh_any_hit(origin, ray / max(len, 1e-30), len) ? 0.0 : 1.0;
}

float sun_light(int light, vec3 p, vec3 n, uint state, int m)
{
  vec3 to_light = -light_texel(light, 5).xyz;
  float value = max(dot(n, to_light), 0.0) * light_texel(light, 1).w / M_PI_F;
  if (value <= 0.0) {
    return 0.0;
  }
  vec3 origin = p + NORMAL_OFFSET * n;
  float tan_half = light_texel(light, 3).w;
  if (tan_half <= 0.0) {
    return bvh_any_hit(origin, to_light, BVH_FAR) ? 0.0 : value;
  }
  vec3 t, b;
  perpendicular_basis(to_light, t, b);
  float visible = 0.0;
  for (int k = 0; k < m * m; k++) {
    vec2 disk = concentric_disk(hashed_stratum(state, k, m)) * tan_half;
    vec3 dir = normalize(to_light + disk.x * t + disk.y * b);
    visible += bvh_any_hit(origin, dir, BVH_FAR) ? 0.0 : 1.0;
  }
  return value * visible / float(m * m);
}

float point_light(int light, int kind, vec3 p, vec3 n, uint state, int m)
{
  vec4 centre = light_texel(light, 2); /* xyz, radius */
  vec3 delta = centre.xyz - p;
  float d2 = dot(delta, delta);
  float dist = sqrt(d2);
  vec3 w = delta / max(dist, 1e-30);
  float radius = centre.w;
  float value = light_texel(light, 1).w / (4.0 * M_PI_F) * max(dot(n, w), 0.0);
  value /= (d2 + radius * radius) * M_PI_F;
  if (kind == 2) { /* spot: smoothstep of the cone's edge, no falloff inside */
    vec4 emit = light_texel(light, 5);
    float cos_half = light_texel(light, 4).w;
    float cos_phi = dot(-w, emit.xyz);
    if (emit.w <= 0.0) {
      value *= cos_phi > cos_half ? 1.0 : 0.0;
    }
    else {
      float x = clamp((cos_phi - cos_half) / ((1.0 - cos_half) * emit.w), 0.0, 1.0);
      value *= x * x * (3.0 - 2.0 * x);
    }
  }
  if (value <= 0.0) {
    return 0.0;
  }
  vec3 origin = p + NORMAL_OFFSET * n;
  if (radius <= 0.0) {
    return value * visible_to(origin, centre.xyz);
  }
  vec3 t, b;
  perpendicular_basis(w, t, b);
  float visible = 0.0;
  for (int k = 0; k < m * m; k++) {
    vec2 disk = concentric_disk(hashed_stratum(state, k, m)) * radius;
    visible += visible_to(origin, centre.xyz + disk.x * t + disk.y * b);
  }
  return value * visible / float(m * m);
}

/* Lambert's formula over the outline, whole polygon above the horizon (∫ cosθ/π dω). */
float polygon_irradiance(int light, int count, vec3 p, vec3 n)
{
  float sum = 0.0;
  vec3 first = normalize(light_texel(light, 8).xyz - p);
  vec3 a = first;
  for (int k = 0; k < count; k++) {
    vec3 b = k + 1 < count ? normalize(light_texel(light, 8 + k + 1).xyz - p) : first;
    vec3 c = cross(a, b);
    float s = length(c);
    sum += atan(s, dot(a, b)) * dot(c / max(s, 1e-30), n);
    a = b;
  }
  return abs(sum) / (2.0 * M_PI_F);
}

float area_light(int light, vec4 head, vec3 p, vec3 n, uint state, int m)
{
  vec3 centre = light_texel(light, 2).xyz;
  vec3 emit = light_texel(light, 5).xyz;
  if (dot(p - centre, emit) <= 0.0) { /* one-sided emitter */
    return 0.0;
  }
  int count = int(head.z);
  bool full = true;
  bool any_above = false;
  for (int k = 0; k < count; k++) {
    float h = dot(light_texel(light, 8 + k).xyz - p, n);
    full = full && h > 0.0;
    any_above = any_above || h > 0.0;
  }
  if (!any_above) {
    return 0.0;
  }
  vec3 ex = light_texel(light, 3).xyz;
  vec3 ey = light_texel(light, 4).xyz;
  vec4 area = light_texel(light, 6); /* area, radiance */
  vec3 origin = p + NORMAL_OFFSET * n;
  float f_sum = 0.0;
  float f_lit = 0.0;
  for (int k = 0; k < m * m; k++) {
    vec2 s = hashed_stratum(state, k, m);
    vec2 unit = head.y > 0.5 ? concentric_disk(s) : s * 2.0 - 1.0;
    vec3 target = centre + unit.x * ex + unit.y * ey;
    vec3 w = target - p;
    float r2 = dot(w, w);
    float f = max(dot(w, n), 0.0) * max(-dot(w, emit), 0.0) / (max(r2, 1e-30) * max(r2, 1e-30));
    f_sum += f;
    if (f > 0.0) {
      f_lit += f * visible_to(origin, target);
    }
  }
  float unshadowed = full ? polygon_irradiance(light, count, p, n)
                          : f_sum / float(m * m) * area.x / M_PI_F;
  return f_sum > 0.0 ? area.y * unshadowed * f_lit / f_sum : 0.0;
}

/* Diffuse Direct of light `light` alone at p (0 for a padding row), with the samples
 * diffuse_direct draws for it. */
vec3 light_direct(int light, vec3 p, vec3 n, uint id, uint seed, int m)
{
  vec4 head = light_texel(light, 0);
  int kind = int(head.x);
  if (kind < 0) {
    return vec3(0.0);
  }
  uint state = point_stream(id, uint(head.w), seed);
  float value;
  if (kind == 0) {
    value = sun_light(light, p, n, state, m);
  }
  else if (kind == 3) {
    value = area_light(light, head, p, n, state, m);
  }
  else {
    value = point_light(light, kind, p, n, state, m);
  }
  return value * light_texel(light, 1).rgb;
}

/* Unit direction from p to light `light`'s centre (a sun: against its travel), as
 * direct_light.light_directions. */
vec3 light_towards(int light, vec3 p)
{
  if (int(light_texel(light, 0).x) == 0) {
    return -light_texel(light, 5).xyz;
  }
  return normalize(light_texel(light, 2).xyz - p);
}

/* Diffuse Direct of all lights at p (normal n facing the viewer), `id` the point's sample id
 * and `m` × `m` strata per light with an extent. */
vec3 diffuse_direct(vec3 p, vec3 n, uint id, uint seed, int m)
{
  vec3 sum = vec3(0.0);
  int count = textureSize(lights, 0).y;
  for (int light = 0; light < count; light++) {
    sum += light_direct(light, p, n, id, seed, m);
  }
  return sum;
}

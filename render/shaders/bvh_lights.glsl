/* Diffuse Direct (irradiance / π, no albedo) of every light at a surface point, with shadow
 * rays through the BVH: a port of voxgi_addon/direct_light.diffuse_direct (its module doc has
 * the light models) with the hashed strata of sampling.hashed_square, so that
 * diffuse_direct(..., sample_ids=ids, seed=seed) draws the same samples.
 * Sampler `lights`: voxgi_addon/light_table.py, one row per light (LIGHT_TEXELS wide); a row
 * of type < 0 is padding. Needs bvh_common.glsl and, before it, light_outline.glsl. */

#define NORMAL_OFFSET 1e-5 /* direct_light._NORMAL_OFFSET: shadow rays start off the surface */

vec4 light_texel(int light, int k)
{
  return texelFetch(lights, ivec2(k, light), 0);
}

/* Cycles' shadow terminator offset (voxgi_addon/gi/terminator.py): a kernel that knows the
 * triangle under its shading point sets its lift (terminator_lift, the geometric normal on the
 * shaded side terminator_ng and the shading normal terminator_n: terminator_set); every shadow
 * ray of the lights below then starts from the point lifted by terminator.amount of it.
 * Zero (the default: gather hits, cache faces) leaves the rays as they were. */
vec3 terminator_lift = vec3(0.0);
vec3 terminator_ng = vec3(0.0);
vec3 terminator_n = vec3(0.0);

/* terminator.amount: the share of the lift a shadow ray toward unit `dir` takes */
float terminator_amount(vec3 dir)
{
  float nl = dot(terminator_n, dir);
  vec3 ng = nl < 0.0 ? -terminator_ng : terminator_ng;
  nl = abs(nl);
  float ngl = dot(ng, dir);
  return nl < TERMINATOR_OFFSET ? clamp(2.0 - (ngl + nl) / TERMINATOR_OFFSET, 0.0, 1.0) :
                                  clamp(1.0 - ngl / TERMINATOR_OFFSET, 0.0, 1.0);
}

/* Is anything in the way of the shadow ray from `origin` in unit direction `dir` within
 * `tmax` (BVH_FAR: to a sun or the sky)? `lifted`: the ray leaves from the start the shadow
 * terminator lifts (terminator_set; a ray toward a point keeps its end there), else from
 * `origin` (a BSDF's ray that finds the sky). */
bool shadow_ray(vec3 origin, vec3 dir, float tmax, bool lifted)
{
  /* one traversal for every case: each call of bvh_any_hit is inlined whole, and llvmpipe's
   * time to build a kernel's machine code grows with every copy (docs/gi_pipeline.md "One
   * traversal per light") */
  float share = lifted && dot(terminator_lift, terminator_lift) > 0.0 ? terminator_amount(dir) :
                                                                        0.0;
  vec3 start = origin;
  vec3 d = dir;
  float len = tmax;
  if (share > 0.0) {
    start = origin + terminator_lift * share;
    if (tmax < BVH_FAR) {
      vec3 ray = origin + dir * tmax - start;
      len = length(ray);
      d = ray / max(len, 1e-30);
    }
  }
  return bvh_any_hit(start, d, len);
}

/* false while light_direct lights a lamp with Cast Shadow off (lights texel 6.z): its shadow
 * rays then meet nothing */
bool lamp_shadows = true;

/* A light sample's shadow ray: lifted. */
bool shadow_hit(vec3 origin, vec3 dir, float tmax)
{
  return lamp_shadows && shadow_ray(origin, dir, tmax, true);
}

/* Unoccluded share of the ray from `origin` to `target`: 1 or 0. */
float visible_to(vec3 origin, vec3 target)
{
  vec3 ray = target - origin;
  float len = length(ray);
  return shadow_hit(origin, ray / max(len, 1e-30), len) ? 0.0 : 1.0;
}

/* The j-th stratum a light's loop over m × m strata draws (direct_light._visible_share): the
 * four corners of the m × m grid first, then the others in order, so that for m ≥ 3 a loop
 * can stop after the corners when they all agree (ADAPTIVE_FROM). */
int stratum_order(int j, int m)
{
  if (j < 4) {
    return j == 0 ? 0 : (j == 1 ? m - 1 : (j == 2 ? m * (m - 1) : m * m - 1));
  }
  int i = j - 4;
  return i < m - 2 ? i + 1 : (i < m * m - m - 2 ? i + 2 : i + 3);
}

#define ADAPTIVE_FROM 3 /* strata sides from which the corners may settle a light's share */

float sun_light(int light, vec3 p, vec3 n, uint state, int m)
{
  vec3 to_light = -light_texel(light, 5).xyz;
  float value = max(dot(n, to_light), 0.0) * light_texel(light, 1).w / M_PI_F;
  if (value <= 0.0) {
    return 0.0;
  }
  vec3 origin = p + surface_offset(p, NORMAL_OFFSET) * n;
  float tan_half = light_texel(light, 3).w;
  vec3 t, b;
  perpendicular_basis(to_light, t, b);
  float visible = 0.0;
  int drawn = 0;
  int rays = tan_half <= 0.0 ? 1 : m * m; /* a sun without a size: one ray at its centre */
  for (int j = 0; j < rays; j++) {
    if (j == 4 && m >= ADAPTIVE_FROM && (visible == 0.0 || visible == 4.0)) {
      break; /* the corners agree: the light is all seen or all hidden */
    }
    vec3 dir = to_light;
    if (tan_half > 0.0) {
      vec2 disk = concentric_disk(hashed_stratum(state, stratum_order(j, m), m)) * tan_half;
      dir = normalize(to_light + disk.x * t + disk.y * b);
    }
    visible += shadow_hit(origin, dir, BVH_FAR) ? 0.0 : 1.0;
    drawn++;
  }
  return value * visible / float(drawn);
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
  vec3 origin = p + surface_offset(p, NORMAL_OFFSET) * n;
  vec3 t, b;
  perpendicular_basis(w, t, b);
  float visible = 0.0;
  int drawn = 0;
  int rays = radius <= 0.0 ? 1 : m * m; /* a point without a size: one ray at its centre */
  for (int j = 0; j < rays; j++) {
    if (j == 4 && m >= ADAPTIVE_FROM && (visible == 0.0 || visible == 4.0)) {
      break; /* the corners agree */
    }
    vec3 target = centre.xyz;
    if (radius > 0.0) {
      vec2 disk = concentric_disk(hashed_stratum(state, stratum_order(j, m), m)) * radius;
      target += disk.x * t + disk.y * b;
    }
    visible += visible_to(origin, target);
    drawn++;
  }
  return value * visible / float(drawn);
}

/* A rectangle seen from o, set up for drawing points uniformly in its solid angle (Ureña,
 * Fajardo & King 2013; sampling.spherical_rectangle, which this ports): the local frame (x, y,
 * z), the corner's coordinates x0, y0, z0 and far edges x1, y1, and the spherical angles'
 * terms b0, b1, k and the solid angle S. */
struct SphereRect {
  vec3 o, x, y, z;
  float x0, y0, z0, x1, y1, b0, b1, k, solid;
};

SphereRect sphere_rect(vec3 o, vec3 corner, vec3 edge_x, vec3 edge_y)
{
  SphereRect r;
  float exl = length(edge_x), eyl = length(edge_y);
  r.o = o;
  r.x = edge_x / exl;
  r.y = edge_y / eyl;
  r.z = cross(r.x, r.y);
  vec3 d = corner - o;
  float z0 = dot(d, r.z);
  if (z0 > 0.0) {
    r.z = -r.z;
  }
  r.z0 = -abs(z0);
  r.x0 = dot(d, r.x);
  r.y0 = dot(d, r.y);
  r.x1 = r.x0 + exl;
  r.y1 = r.y0 + eyl;
  vec3 v00 = vec3(r.x0, r.y0, r.z0), v01 = vec3(r.x0, r.y1, r.z0);
  vec3 v10 = vec3(r.x1, r.y0, r.z0), v11 = vec3(r.x1, r.y1, r.z0);
  vec3 n0 = normalize(cross(v00, v10)), n1 = normalize(cross(v10, v11));
  vec3 n2 = normalize(cross(v11, v01)), n3 = normalize(cross(v01, v00));
  float g0 = acos(clamp(-dot(n0, n1), -1.0, 1.0)), g1 = acos(clamp(-dot(n1, n2), -1.0, 1.0));
  float g2 = acos(clamp(-dot(n2, n3), -1.0, 1.0)), g3 = acos(clamp(-dot(n3, n0), -1.0, 1.0));
  r.b0 = n0.z;
  r.b1 = n2.z;
  r.k = 2.0 * M_PI_F - g2 - g3;
  r.solid = max(g0 + g1 - r.k, 0.0);
  return r;
}

/* The point of `r` at uv in [0, 1)²; `fallback` where the solid angle vanishes. */
vec3 sphere_rect_point(SphereRect r, vec2 uv, vec3 fallback)
{
  if (r.solid <= 1e-7) {
    return fallback;
  }
  float au = uv.x * r.solid + r.k;
  float fu = (cos(au) * r.b0 - r.b1) / sin(au);
  float cu = clamp(sign(fu) / sqrt(fu * fu + r.b0 * r.b0), -1.0, 1.0);
  float xu = clamp(-(cu * r.z0) / sqrt(max(1.0 - cu * cu, 1e-30)), r.x0, r.x1);
  float dd = sqrt(xu * xu + r.z0 * r.z0);
  float h0 = r.y0 / sqrt(dd * dd + r.y0 * r.y0);
  float h1 = r.y1 / sqrt(dd * dd + r.y1 * r.y1);
  float hv = h0 + uv.y * (h1 - h0);
  float hv2 = hv * hv;
  float yv = hv2 < 1.0 - 1e-6 ? hv * dd / sqrt(max(1.0 - hv2, 1e-30)) : r.y1;
  vec3 q = r.o + xu * r.x + yv * r.y + r.z0 * r.z;
  return any(isnan(q)) || any(isinf(q)) ? fallback : q;
}

float area_light(int light, vec4 head, vec3 p, vec3 n, uint state, int m)
{
  vec3 centre = light_texel(light, 2).xyz;
  vec3 emit = light_texel(light, 5).xyz;
  if (dot(p - centre, emit) <= 0.0) { /* one-sided emitter */
    return 0.0;
  }
  int count = int(head.z);
  vec3 aim;
  float unshadowed = polygon_irradiance(light, count, p, n, aim);
  if (unshadowed <= 0.0) {
    return 0.0;
  }
  vec3 ex = light_texel(light, 3).xyz;
  vec3 ey = light_texel(light, 4).xyz;
  vec4 area = light_texel(light, 6); /* area, radiance */
  vec3 origin = p + surface_offset(p, NORMAL_OFFSET) * n;
  float f_sum = 0.0;
  float f_lit = 0.0;
  /* a rectangle (its edges perpendicular) is drawn by solid angle, as Cycles draws it: a
   * sample's share is its cosine at p alone; a disk or an ellipse by area, its share
   * cos·cos / r² (direct_light._area) */
  bool by_angle = head.y < 0.5 && abs(dot(ex, ey)) <= 1e-6 * length(ex) * length(ey);
  SphereRect rect;
  if (by_angle) {
    rect = sphere_rect(p, centre - ex - ey, 2.0 * ex, 2.0 * ey);
  }
  for (int j = 0; j <= m * m; j++) {
    vec3 target = aim;
    float f = 1.0;
    if (j == m * m) {
      if (f_sum > 0.0) {
        break;
      }
      /* no sample above the horizon (one sample at a bounce hit): one ray to the middle of
       * the part above (direct_light._area), its share f_lit */
    }
    else {
      if (j == 4 && m >= ADAPTIVE_FROM && f_sum > 0.0 && (f_lit == 0.0 || f_lit == f_sum)) {
        break; /* the corners above the horizon agree */
      }
      vec2 s = hashed_stratum(state, stratum_order(j, m), m);
      vec2 unit = head.y > 0.5 ? concentric_disk(s) : s * 2.0 - 1.0;
      target = by_angle ? sphere_rect_point(rect, s, centre) : centre + unit.x * ex + unit.y * ey;
      vec3 w = target - p;
      float r2 = dot(w, w);
      f = by_angle ? max(dot(w, n), 0.0) / sqrt(max(r2, 1e-30)) :
                     max(dot(w, n), 0.0) * max(-dot(w, emit), 0.0) /
                         (max(r2, 1e-30) * max(r2, 1e-30));
      f_sum += f;
    }
    if (f > 0.0) {
      f_lit += f * visible_to(origin, target);
    }
  }
  return area.y * unshadowed * (f_sum > 0.0 ? f_lit / f_sum : f_lit);
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
  lamp_shadows = light_texel(light, 6).z < 0.5;
  /* a kernel built for a scene without a kind of light leaves its code out (BVH_NO_SUN,
   * BVH_NO_AREA, BVH_NO_POINT: gpu_bvh.bvh_shader); llvmpipe pays for a branch whether a lane
   * takes it or not */
  float value = 0.0;
#ifndef BVH_NO_SUN
  if (kind == 0) {
    value = sun_light(light, p, n, state, m);
  }
#endif
#ifndef BVH_NO_AREA
  if (kind == 3) {
    value = area_light(light, head, p, n, state, m);
  }
#endif
#ifndef BVH_NO_POINT
  if (kind == 1 || kind == 2) {
    value = point_light(light, kind, p, n, state, m);
  }
#endif
  lamp_shadows = true;
  return value * light_texel(light, 1).rgb;
}

/* Unit direction from p with normal n to light `light` as direct_light.light_aims: to an area
 * light's part above the horizon of (p, n) (the clipped outline's corners' mean) where it has
 * one, else as light_towards. */
vec3 light_towards(int light, vec3 p);
vec3 light_aim(int light, vec3 p, vec3 n)
{
#ifndef BVH_NO_AREA
  vec4 head = light_texel(light, 0);
  if (int(head.x) == 3) {
    vec3 aim;
    if (polygon_irradiance(light, int(head.z), p, n, aim) > 0.0) {
      vec3 d = aim - p;
      return d / max(length(d), 1e-12);
    }
  }
#endif
  return light_towards(light, p);
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

/* ---- The world as a light (voxgi_addon/gi/world_light.py): world_map.glsl reads its table
 * (world_header, world_on, world_uniform, world_pixel, world_radiance_at, world_unshadowed).
 * LUMA: light_outline.glsl. */

/* Index of the first of `count` inclusive CDF entries above u: the row CDF (column W's x) or
 * row i's column CDF (its alpha). */
int world_cdf_search(bool rows, int i, int w, int count, float u)
{
  int lo = 0;
  int hi = count - 1;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    float cdf = rows ? texelFetch(world_map, ivec2(w, mid), 0).x :
                       texelFetch(world_map, ivec2(mid, i), 0).a;
    if (cdf <= u) {
      lo = mid + 1;
    }
    else {
      hi = mid;
    }
  }
  return lo;
}

/* world_light.sample_world: the row, then the column by their inclusive CDFs, then uniform in
 * z and azimuth inside the pixel. */
vec3 world_sample(vec2 u, int h, int w)
{
  int i = world_cdf_search(true, 0, w, h, u.x);
  float low = i > 0 ? texelFetch(world_map, ivec2(w, i - 1), 0).x : 0.0;
  float f0 = clamp((u.x - low) / max(texelFetch(world_map, ivec2(w, i), 0).x - low, 1e-30),
                   0.0, 1.0);
  int j = world_cdf_search(false, i, w, w, u.y);
  float left = j > 0 ? texelFetch(world_map, ivec2(j - 1, i), 0).a : 0.0;
  float right = texelFetch(world_map, ivec2(j, i), 0).a;
  float f1 = clamp((u.y - left) / max(right - left, 1e-30), 0.0, 1.0);
  float z_top = cos(float(i) * M_PI_F / float(h));
  float z_bottom = cos(float(i + 1) * M_PI_F / float(h));
  float z = z_top + f0 * (z_bottom - z_top);
  float phi = -M_PI_F + (float(j) + f1) * (2.0 * M_PI_F / float(w));
  float r = sqrt(max(0.0, 1.0 - z * z));
  return vec3(r * cos(phi), r * sin(phi), z);
}

/* The map's sun (world_light.Sun): `count` pixels row-major from row `first_row` of the table,
 * each (row, column, its row's inclusive CDF, its inclusive CDF within the row). */
vec4 world_sun_texel(int k, int first_row)
{
  int width = textureSize(world_map, 0).x;
  return texelFetch(world_map, ivec2(k % width, first_row + k / width), 0);
}

/* world_light.sample_sun: the row by u.x, the pixel in it by u.y (binary searches over the
 * sun's texels), then uniform in z and azimuth inside the pixel; pdf lum(L) / the sun's total. */
vec3 world_sun_sample(vec2 u, int h, int w, int first_row, int count)
{
  int lo = 0;
  int hi = count - 1;
  while (lo < hi) { /* the row's first pixel: the first whose row CDF exceeds u.x */
    int mid = (lo + hi) / 2;
    if (world_sun_texel(mid, first_row).z > u.x) {
      hi = mid;
    }
    else {
      lo = mid + 1;
    }
  }
  int first = lo;
  float low = first > 0 ? world_sun_texel(first - 1, first_row).z : 0.0;
  float high = world_sun_texel(first, first_row).z;
  float f0 = clamp((u.x - low) / max(high - low, 1e-30), 0.0, 1.0);
  hi = count;
  while (lo < hi) { /* the row's end: the first pixel of a later row */
    int mid = (lo + hi) / 2;
    if (world_sun_texel(mid, first_row).z > high) {
      hi = mid;
    }
    else {
      lo = mid + 1;
    }
  }
  int end = lo;
  lo = first;
  hi = end - 1;
  while (lo < hi) { /* the pixel: the row's first whose CDF exceeds u.y */
    int mid = (lo + hi) / 2;
    if (world_sun_texel(mid, first_row).w > u.y) {
      hi = mid;
    }
    else {
      lo = mid + 1;
    }
  }
  vec4 texel = world_sun_texel(lo, first_row);
  float left = lo > first ? world_sun_texel(lo - 1, first_row).w : 0.0;
  float f1 = clamp((u.y - left) / max(texel.w - left, 1e-30), 0.0, 1.0);
  float i = texel.x;
  float z_top = cos(i * M_PI_F / float(h));
  float z_bottom = cos((i + 1.0) * M_PI_F / float(h));
  float z = z_top + f0 * (z_bottom - z_top);
  float phi = -M_PI_F + (texel.y + f1) * (2.0 * M_PI_F / float(w));
  float r = sqrt(max(0.0, 1.0 - z * z));
  return vec3(r * cos(phi), r * sin(phi), z);
}

/* A light's shadowed value from its exact unshadowed `value` and its rays' Σ f (f_sum) and
 * Σ seen f (f_lit) over m × m strata (world_light.hidden_less): the value less the hidden
 * rays' estimate, held at 0 from DIFFERENCE_STRATA strata (m ≥ 2: a pixel's light); a bounce
 * hit's or a probe ray's single stratum is not held (the mean of the rays that read it
 * counts), nor a sub-pixel sample's share of its pixel's strata (direct_light.world_block). */
vec3 hidden_less(vec3 value, vec3 f_sum, vec3 f_lit, int m)
{
  vec3 light = value - (f_sum - f_lit) / (float(m * m) * M_PI_F);
#ifdef STRATA_BLOCK
  bool share = STRATA_BLOCK.x > m; /* a sub-pixel sample's share of its pixel's strata */
#else
  bool share = false;
#endif
  return m >= 2 && !share ? max(light, vec3(0.0)) : light;
}

/* Diffuse Direct of the world (world_light.world_direct): the unshadowed table value less
 * the estimate of its hidden part from one map sample and one cosine sample per stratum
 * (Σ over the hidden rays of L cos / (p_map + p_cos), / m² π), held at 0 or above: exact where
 * every ray sees the world, unbiased where some are hidden (the visible share Σ seen / Σ all
 * was a ratio of estimates, biased there: docs/gi_pipeline.md "The world's light where it is
 * partly hidden"). */
/* The world's Diffuse Direct at p (world_light.world_direct) and, with `lobe` (kernels with
 * principled.glsl), in `glossy` the radiance a bounce hit's glossy lobe (Principled `base`,
 * `params`) reflects of it toward `v` from the same rays: each ray's L V f / (m² (p_map +
 * p_cos)), the balance heuristic of both techniques. */
/* The variance of the luminance of the last world_direct_lobe's estimate of the world's hidden
 * part (its rays taken as independent: an upper bound under the strata), for the filter of a
 * pixel's world light (bvh_direct.glsl's alpha, denoise.glsl options.w). */
float world_variance = 0.0;

/* `single` (a bounce hit's): one ray a stratum, by the map where the stratum's x is under ½,
 * else by the cosine, x stretched back over [0, 1), each ray over the techniques' mean density
 * (one-sample MIS, world_light.one_technique; docs/gi_pipeline.md "One world ray a bounce
 * hit"). */
vec3 world_direct_lobe(vec3 p, vec3 n, uint state, int m, bool lobe, vec3 v, vec3 base,
                       vec3 params, bool single, out vec3 glossy)
{
  glossy = vec3(0.0);
  world_variance = 0.0;
  vec4 head = world_header();
  int h = int(head.x);
  int w = int(head.y);
  vec3 value = world_unshadowed(n, h);
  if (max(value.r, max(value.g, value.b)) <= 0.0) {
    return value;
  }
  vec3 origin = p + surface_offset(p, NORMAL_OFFSET) * n;
  vec3 t, b;
  perpendicular_basis(n, t, b);
  vec3 f_sum = vec3(0.0);
  vec3 f_lit = vec3(0.0);
  bool uniform_sky = world_uniform();
  bool split = single && !uniform_sky;
  /* a pixel's strata trace the map's sun apart (world_light._sun_hidden): the rays that land
   * in it carry nothing here and are not traced */
  ivec2 last = ivec2(0, textureSize(world_map, 0).y - 1);
  int sun_count = int(texelFetch(world_map, last + ivec2(1, 0), 0).w + 0.5);
#ifdef STRATA_BLOCK
  bool share = STRATA_BLOCK.x > m; /* a sub-pixel sample's share of its pixel's strata */
#else
  bool share = false;
#endif
  bool sunny = sun_count > 0 && !single && !lobe && !uniform_sky && m >= 2;
  /* a whole image's pixel centres: the rest of the map over fewer strata where the world's
   * filter averages them over a window wide enough and on one surface
   * (passes.world_strata_side, world_fewer_pixels) */
  int ms = m;
#ifdef WORLD_STRATA
  /* (one flag a work group, uniform over it: gpu_bvh.world_fewer_texture) */
  if (!share && !single && !lobe && WORLD_STRATA > 0 &&
      texelFetch(world_fewer, ivec2(gl_WorkGroupID.xy), 0).x > 0.5) {
    ms = WORLD_STRATA;
  }
#endif
  vec4 sun_head = sunny ? texelFetch(world_map, last + ivec2(2, 0), 0) : vec4(0.0);
  float hidden_sum = 0.0, hidden_squares = 0.0; /* Σ, Σ² of a hidden ray's lum(f) / π */
  /* F12's pixel centres (hidden.x = 1, uniform over the dispatch): the rest of the map's
   * hidden part is the diffuse gather's (bvh_gather.glsl out_hidden), filtered and upsampled
   * (world_hidden, rgb; docs/gi_pipeline.md "The world's light at the gather points"): no rays
   * of their own for it */
  bool given = false;
#ifdef WORLD_HIDDEN
  given = !share && !single && !lobe && WORLD_HIDDEN.x > 0.5;
#endif
  /* uniform: cosine only; split: one loop, each stratum drawing its technique */
  for (int pass = given ? 2 : (uniform_sky || split ? 1 : 0); pass < 2; pass++) {
    for (int k = 0; k < ms * ms; k++) {
      vec2 s = ms == m ? hashed_stratum(state, k, m) : whole_stratum(state, k, ms);
      int technique = pass;
      if (split) {
        technique = s.x < 0.5 ? 0 : 1;
        s.x = s.x < 0.5 ? 2.0 * s.x : 2.0 * s.x - 1.0;
      }
      vec3 dir;
      if (technique == 0) {
        dir = world_sample(s, h, w);
      }
      else {
        vec2 disk = concentric_disk(s);
        float lift = sqrt(max(0.0, 1.0 - dot(disk, disk)));
        dir = normalize(disk.x * t + disk.y * b + lift * n);
      }
      float cos_n = dot(dir, n);
      if (cos_n <= 0.0) {
        continue;
      }
      vec3 radiance = world_radiance_at(world_pixel(dir, h, w));
      float pdf = ((uniform_sky ? 0.0 : dot(radiance, LUMA) / head.w) + cos_n / M_PI_F) *
                  (split ? 0.5 : 1.0);
      vec3 f = radiance * (cos_n / max(pdf, 1e-30));
      if (sunny && dot(radiance, LUMA) > sun_head.x) {
        f = vec3(0.0);
      }
      f_sum += f;
      /* the map's rays as Cycles' light samples (lifted by the shadow terminator offset),
       * the cosine ones as its BSDF's rays that find the sky (not lifted) */
      bool seen = max(f.r, max(f.g, f.b)) > 0.0 &&
          !shadow_ray(origin, dir, BVH_FAR, technique == 0);
      if (!seen) {
        float hidden = dot(f, LUMA) / M_PI_F;
        hidden_sum += hidden;
        hidden_squares += hidden * hidden;
      }
      else {
        f_lit += f;
#ifdef PRINCIPLED_IOR
        if (lobe) {
          glossy += radiance * principled_glossy_reflectance(base, params.x, params.y, params.z,
                                                             n, v, dir) / max(pdf, 1e-30);
        }
#endif
      }
    }
  }
  glossy /= float(ms * ms);
  /* the hidden part's estimate is Σ h / m² over N = techniques × m² rays: T var(h) / m² */
  float rays = float(ms * ms * (uniform_sky || split ? 1 : 2));
  float spread = max(hidden_squares - hidden_sum * hidden_sum / rays, 0.0) / max(rays - 1.0, 1.0);
  world_variance = rays / float(ms * ms) * spread / float(ms * ms);
  vec3 rest_hidden = (f_sum - f_lit) / (float(ms * ms) * M_PI_F);
#ifdef WORLD_HIDDEN
  if (given) {
    rest_hidden = texelFetch(world_hidden, ivec2(gl_GlobalInvocationID.xy), 0).rgb;
    world_variance = 0.0;
  }
#endif
  if (!sunny) {
    return given ? max(value - rest_hidden, vec3(0.0)) : hidden_less(value, f_sum, f_lit, ms);
  }
  /* the sun: one ray a stratum by its power, the corners first; where those above the
   * horizon agree the others are not drawn (as a lamp's); Σ hidden f / (drawn π) */
  vec3 sun_hidden = vec3(0.0);
  float sun_sum = 0.0, sun_squares = 0.0;
  int drawn = 0, sun_seen = 0, sun_blocked = 0;
  for (int j = 0; j < m * m; j++) {
    if (j == 4 && m >= ADAPTIVE_FROM && (sun_seen == 0) != (sun_blocked == 0)) {
      break;
    }
    vec3 dir = world_sun_sample(hashed_stratum(state, stratum_order(j, m), m), h, w,
                                h + int(head.z), sun_count);
    drawn++;
    float cos_n = dot(dir, n);
    if (cos_n <= 0.0) {
      continue;
    }
    vec3 radiance = world_radiance_at(world_pixel(dir, h, w));
    vec3 f = radiance * (cos_n / max(dot(radiance, LUMA) / sun_head.y, 1e-30));
    if (shadow_ray(origin, dir, BVH_FAR, true)) {
      sun_blocked++;
      sun_hidden += f;
      float hidden = dot(f, LUMA) / M_PI_F;
      sun_sum += hidden;
      sun_squares += hidden * hidden;
    }
    else {
      sun_seen++;
    }
  }
  float count = float(drawn);
  world_variance += max(sun_squares - sun_sum * sun_sum / count, 0.0) / max(count - 1.0, 1.0) /
                    count;
  vec3 light = value - rest_hidden - sun_hidden / (count * M_PI_F);
  return share ? light : max(light, vec3(0.0));
}

vec3 world_direct(vec3 p, vec3 n, uint state, int m)
{
  vec3 unused;
  return world_direct_lobe(p, n, state, m, false, n, vec3(0.0), vec3(0.0), false, unused);
}

/* The world's Diffuse Direct with the samples diffuse_direct draws for it (its hash stream,
 * its index after the lamps, is the header's texel 1.y); 0 without a world. */
vec3 world_light_lobe(vec3 p, vec3 n, uint id, uint seed, int m, bool lobe, vec3 v, vec3 base,
                      vec3 params, bool single, out vec3 glossy)
{
  glossy = vec3(0.0);
#ifdef BVH_NO_WORLD
  return vec3(0.0);
#else
  if (!world_on()) {
    return vec3(0.0);
  }
  uint stream = uint(texelFetch(world_map, ivec2(1, textureSize(world_map, 0).y - 1), 0).y);
  return world_direct_lobe(p, n, point_stream(id, stream, seed), m, lobe, v, base, params,
                           single, glossy);
#endif
}

/* The world's rest toward unit `d`: the map's radiance there, 0 in its sun's texels where
 * `sun_apart` (a map's sun traced apart: world_direct_lobe's sunny) and 0 without a world.
 * The diffuse gather adds it up over its rays that a surface hides from the world
 * (bvh_gather.glsl out_hidden; docs/gi_pipeline.md "The world's light at the gather points"). */
vec3 world_rest_radiance(vec3 d, bool sun_apart)
{
#ifdef BVH_NO_WORLD
  return vec3(0.0);
#else
  if (!world_on()) {
    return vec3(0.0);
  }
  vec4 head = world_header();
  vec3 radiance = world_radiance_at(world_pixel(d, int(head.x), int(head.y)));
  ivec2 last = ivec2(0, textureSize(world_map, 0).y - 1);
  int sun_count = int(texelFetch(world_map, last + ivec2(1, 0), 0).w + 0.5);
  bool sun = sun_apart && sun_count > 0 && !world_uniform() &&
             dot(radiance, LUMA) > texelFetch(world_map, last + ivec2(2, 0), 0).x;
  return sun ? vec3(0.0) : radiance;
#endif
}

vec3 world_light_direct(vec3 p, vec3 n, uint id, uint seed, int m)
{
  vec3 unused;
  return world_light_lobe(p, n, id, seed, m, false, n, vec3(0.0), vec3(0.0), false, unused);
}

/* ---- Emissive triangles as a light (voxgi_addon/gi/emitters.py; sampler `emitters` holds
 * emitters.emitter_table: per triangle (corner, radiance channel) × 3 and its power CDF, and a
 * header row (count, total power, stream, on)). */

vec4 emitter_header()
{
  return texelFetch(emitters, ivec2(0, textureSize(emitters, 0).y - 1), 0);
}

/* (first row, count) of the triangles the exact sums run over: the emitters' own, or past
 * them the proxy standing in for them where they are many (emitters.EmitterLight.sums). */
ivec2 emitter_sums()
{
  vec4 rows = texelFetch(emitters, ivec2(1, textureSize(emitters, 0).y - 1), 0);
  return ivec2(int(rows.x + 0.5), int(rows.y + 0.5));
}

/* Lambert's term of the edge (a, b) (relative to the point) toward normal n added to sum:
 * θ × the great circle's unit normal · n. */
void form_factor_edge(vec3 a, vec3 b, vec3 n, inout float sum)
{
  float la = length(a);
  float lb = length(b);
  a = la > 0.0 ? a / la : vec3(0.0);
  b = lb > 0.0 ? b / lb : vec3(0.0);
  vec3 c = cross(a, b);
  float s = length(c);
  if (s > 1e-12) {
    sum += atan(s, dot(a, b)) * dot(c / s, n);
  }
}

/* The edge (a, b) of a triangle with heights ha, hb above the point's tangent plane, clipped to
 * the part above (Sutherland-Hodgman's crossing a + t (b - a), t = h_a / (h_a - h_b)), into
 * sum; where it leaves the part above, its crossing is the clipped polygon's exit, where it
 * enters, its entry. */
void form_factor_clipped_edge(vec3 a, vec3 b, float ha, float hb, vec3 n, inout float sum,
                              inout vec3 exit, inout vec3 entry, inout int crossings)
{
  bool in_a = ha >= 0.0;
  bool in_b = hb >= 0.0;
  if (in_a != in_b) {
    float d = ha - hb;
    float s = d != 0.0 ? ha / d : 0.0;
    vec3 cut = a + s * (b - a);
    crossings++;
    if (in_a) {
      exit = cut;
      b = cut;
    }
    else {
      entry = cut;
      a = cut;
    }
  }
  if (in_a || in_b) {
    form_factor_edge(a, b, n, sum);
  }
}

/* ∫ max(n·ω, 0)/π dω over triangle t clipped to the horizon of (p, n), either side
 * (emitters.clipped_form_factors): Lambert's formula over each edge's part above the horizon
 * and the clipped polygon's chord along it (from its exit to its entry), the polygon never
 * held in an array (a local array indexed by a running count is slow to index on llvmpipe). */
float clipped_form_factor(int t, vec3 p, vec3 n)
{
  vec3 a = texelFetch(emitters, ivec2(0, t), 0).xyz - p;
  vec3 b = texelFetch(emitters, ivec2(1, t), 0).xyz - p;
  vec3 c = texelFetch(emitters, ivec2(2, t), 0).xyz - p;
  float ha = dot(a, n);
  float hb = dot(b, n);
  float hc = dot(c, n);
  if (ha < 0.0 && hb < 0.0 && hc < 0.0) {
    return 0.0;
  }
  float sum = 0.0;
  vec3 exit = vec3(0.0);
  vec3 entry = vec3(0.0);
  int crossings = 0;
  form_factor_clipped_edge(a, b, ha, hb, n, sum, exit, entry, crossings);
  form_factor_clipped_edge(b, c, hb, hc, n, sum, exit, entry, crossings);
  form_factor_clipped_edge(c, a, hc, ha, n, sum, exit, entry, crossings);
  if (crossings == 2) {
    form_factor_edge(exit, entry, n, sum);
  }
  return abs(sum) / (2.0 * M_PI_F);
}

/* Does triangle t light the side of it where p is (emitters.EmitterLight.sides)? A proxy's
 * triangle (margin > 0: emitters.proxy_triangles) only where p lies beyond its margin from its
 * plane (emitters._facing), so that the surface it stands in for is not lit by it. */
bool emitter_facing(int t, vec3 p)
{
  vec2 side_margin = texelFetch(emitters, ivec2(3, t), 0).yz;
  float side = side_margin.x;
  if (side == 0.0 && side_margin.y <= 0.0) {
    return true;
  }
  vec3 c0 = texelFetch(emitters, ivec2(0, t), 0).xyz;
  vec3 normal = cross(texelFetch(emitters, ivec2(1, t), 0).xyz - c0,
                      texelFetch(emitters, ivec2(2, t), 0).xyz - c0);
  float height = dot(p - c0, normal);
  float band = side_margin.y * length(normal);
  return side == 0.0 ? abs(height) > band : side * height > band;
}

/* A point on the emitters drawn by power from u (emitters.sample_points): its triangle t and
 * the point. */
vec3 emitter_sample(vec2 u, int count, out int t)
{
  int lo = 0;
  int hi = count - 1;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (texelFetch(emitters, ivec2(3, mid), 0).x <= u.x) {
      lo = mid + 1;
    }
    else {
      hi = mid;
    }
  }
  t = lo;
  float low = t > 0 ? texelFetch(emitters, ivec2(3, t - 1), 0).x : 0.0;
  float r = clamp((u.x - low) / max(texelFetch(emitters, ivec2(3, t), 0).x - low, 1e-30), 0.0,
                  1.0);
  float s = sqrt(r);
  return (1.0 - s) * texelFetch(emitters, ivec2(0, t), 0).xyz +
         (s * (1.0 - u.y)) * texelFetch(emitters, ivec2(1, t), 0).xyz +
         (s * u.y) * texelFetch(emitters, ivec2(2, t), 0).xyz;
}

/* The emitters' exact unshadowed Diffuse Direct at p lifted by NORMAL_OFFSET, as
 * emitters_direct_lobe lifts it (emitters.unshadowed_sum): Σ_t L_t clipped_form_factor over
 * the triangles lighting p's side, O(triangles); a sub-pixel pass takes its pixel centre's
 * where it sees the centre's surface (bvh_direct.glsl). `evaluate` false: 0, no triangle
 * visited. */
vec3 emitters_unshadowed(vec3 p, vec3 n, bool evaluate)
{
  ivec2 rows = emitter_sums();
  p += surface_offset(p, NORMAL_OFFSET) * n;
  vec3 value = vec3(0.0);
  for (int t = rows.x; t < rows.x + rows.y && evaluate; t++) {
    float factor = emitter_facing(t, p) ? clipped_form_factor(t, p, n) : 0.0;
    if (factor > 0.0) {
      value += factor * vec3(texelFetch(emitters, ivec2(0, t), 0).w,
                             texelFetch(emitters, ivec2(1, t), 0).w,
                             texelFetch(emitters, ivec2(2, t), 0).w);
    }
  }
  return value;
}

/* The distance from p to the nearest point of emissive triangle t (emitters.triangle_distances;
 * Ericson's closest point on a triangle): the field of the emitters' light is trusted between
 * gather points only as far as they lie well inside it (upsample.glsl UPSAMPLE_FIELD). */
float emitter_distance(int t, vec3 p)
{
  vec3 a = texelFetch(emitters, ivec2(0, t), 0).xyz;
  vec3 b = texelFetch(emitters, ivec2(1, t), 0).xyz;
  vec3 c = texelFetch(emitters, ivec2(2, t), 0).xyz;
  vec3 ab = b - a, ac = c - a, ap = p - a;
  float d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) {
    return length(ap);
  }
  vec3 bp = p - b;
  float d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) {
    return length(bp);
  }
  float vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    return length(ap - d1 / (d1 - d3) * ab);
  }
  vec3 cp = p - c;
  float d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) {
    return length(cp);
  }
  float vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    return length(ap - d2 / (d2 - d6) * ac);
  }
  float va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
    return length(bp - (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b));
  }
  float denom = 1.0 / max(va + vb + vc, 1e-30);
  return length(ap - ab * (vb * denom) - ac * (vc * denom));
}

/* The distance from p to the nearest emissive triangle that can light it: facing p (a closed
 * emitter's outside, emitter_facing) with a corner above p's tangent plane (normal n). An
 * emitter's own points (the panel, the glowing sphere) are not near themselves
 * (emitters.emitter_distances). */
float emitters_distance(vec3 p, vec3 n)
{
  ivec2 rows = emitter_sums();
  float nearest = 1e30;
  for (int t = rows.x; t < rows.x + rows.y; t++) {
    float above = max(max(dot(texelFetch(emitters, ivec2(0, t), 0).xyz - p, n),
                          dot(texelFetch(emitters, ivec2(1, t), 0).xyz - p, n)),
                      dot(texelFetch(emitters, ivec2(2, t), 0).xyz - p, n));
    if (above > 0.0 && emitter_facing(t, p)) {
      nearest = min(nearest, emitter_distance(t, p));
    }
  }
  return nearest;
}

/* Diffuse Direct of the emissive triangles (emitters.emitters_direct): the exact unshadowed
 * sum (emitters_unshadowed; known.rgb where known.w > 0.5, a pixel centre's) less the
 * estimate of its hidden part from one point per stratum, sampled by power; not `exact` (bounce
 * hits): per stratum the picked triangle's own exact light over its pick's chance less its
 * sample's where hidden (emitters.emitters_direct). With `lobe` (kernels with principled.glsl) `glossy`
 * gets what a bounce hit's glossy lobe reflects of them toward `v` from the same rays (mean of
 * L V f |cos_l| / (r² p_area)). */
vec3 emitters_direct_lobe(vec3 p, vec3 n, uint state, int m, bool exact, vec4 known, bool lobe,
                          vec3 v, vec3 base, vec3 params, out vec3 glossy)
{
  glossy = vec3(0.0);
  vec4 head = emitter_header();
  int count = int(head.x);
  bool given = known.w > 0.5;
  vec3 sum = emitters_unshadowed(p, n, exact && !given); /* else no triangle visited */
  vec3 value = exact ? (given ? known.rgb : sum) : vec3(1.0);
  p += surface_offset(p, NORMAL_OFFSET) * n; /* as direct_light._emitters lifts the point */
  if (max(value.r, max(value.g, value.b)) <= 0.0) {
    return value;
  }
  vec3 origin = p;
  vec3 f_sum = vec3(0.0);
  vec3 f_lit = vec3(0.0);
  vec3 f_exact = vec3(0.0); /* Σ π L_t FF_t / P_t of the picked triangles (not `exact`) */
  for (int k = 0; k < m * m; k++) {
    vec2 u = hashed_stratum(state, k, m);
    int t;
    vec3 target = emitter_sample(u, count, t);
    vec3 c0 = texelFetch(emitters, ivec2(0, t), 0).xyz;
    vec3 c1 = texelFetch(emitters, ivec2(1, t), 0).xyz;
    vec3 c2 = texelFetch(emitters, ivec2(2, t), 0).xyz;
    vec3 radiance = vec3(texelFetch(emitters, ivec2(0, t), 0).w,
                         texelFetch(emitters, ivec2(1, t), 0).w,
                         texelFetch(emitters, ivec2(2, t), 0).w);
    vec3 w = target - p;
    float r2 = dot(w, w);
    float dist = sqrt(r2);
    vec3 d = w / max(dist, 1e-30);
    vec3 normal_area = cross(c1 - c0, c2 - c0);
    vec3 normal = normal_area / max(length(normal_area), 1e-30);
    float g = max(dot(d, n), 0.0) * abs(dot(d, normal)) / max(r2, 1e-30) /
              max(dot(radiance, LUMA) / head.y, 1e-30);
    bool facing = emitter_facing(t, p);
    g = facing ? g : 0.0;
    vec3 f = radiance * g;
    f_sum += f;
    if (!exact && facing) { /* the picked triangle's exact unshadowed light */
      float pick = 0.5 * length(normal_area) * dot(radiance, LUMA) / head.y;
      f_exact += radiance * (clipped_form_factor(t, p, n) * M_PI_F / max(pick, 1e-30));
    }
    if (g > 0.0 && !shadow_hit(origin, d, dist)) {
      f_lit += f;
#ifdef PRINCIPLED_IOR
      if (lobe) {
        glossy += radiance * (abs(dot(d, normal)) / max(r2, 1e-30) /
                              max(dot(radiance, LUMA) / head.y, 1e-30)) *
                  principled_glossy_reflectance(base, params.x, params.y, params.z, n, v, d);
      }
#endif
    }
  }
  glossy /= float(m * m);
  if (!exact) { /* each picked triangle's exact light less its sample's if hidden */
    return (f_exact - (f_sum - f_lit)) / (M_PI_F * float(m * m));
  }
  /* a pixel's light: held at 0 whatever its strata (world_light.hidden_less's difference) */
  return max(value - (f_sum - f_lit) / (float(m * m) * M_PI_F), vec3(0.0));
}

/* The emitters' Diffuse Direct with the samples diffuse_direct draws for them (their stream
 * is the header's z); 0 when nothing emits. */
vec3 emitters_direct(vec3 p, vec3 n, uint state, int m, bool exact)
{
  vec3 unused;
  return emitters_direct_lobe(p, n, state, m, exact, vec4(0.0), false, n, vec3(0.0), vec3(0.0),
                              unused);
}

vec3 emitters_light_lobe(vec3 p, vec3 n, uint id, uint seed, int m, bool exact, vec4 known,
                         bool lobe, vec3 v, vec3 base, vec3 params, out vec3 glossy)
{
  glossy = vec3(0.0);
#ifdef BVH_NO_EMITTERS
  return vec3(0.0);
#else
  vec4 head = emitter_header();
  if (head.w < 0.5) {
    return vec3(0.0);
  }
  return emitters_direct_lobe(p, n, point_stream(id, uint(head.z), seed), m, exact, known,
                              lobe, v, base, params, glossy);
#endif
}

vec3 emitters_light_direct(vec3 p, vec3 n, uint id, uint seed, int m, bool exact, vec4 known)
{
  vec3 unused;
  return emitters_light_lobe(p, n, id, seed, m, exact, known, false, n, vec3(0.0), vec3(0.0),
                             unused);
}

/* Diffuse Direct of all lights at p (normal n facing the viewer), `id` the point's sample id
 * and `m` × `m` strata per light with an extent, the world and the emitters included; known :
 * the emitters' exact unshadowed sum at p when known.w > 0.5 (emitters_direct_lobe). */
vec3 diffuse_direct(vec3 p, vec3 n, uint id, uint seed, int m, vec4 known)
{
  vec3 sum = vec3(0.0);
  int count = textureSize(lights, 0).y;
  for (int light = 0; light < count; light++) {
    sum += light_direct(light, p, n, id, seed, m);
  }
  return sum + world_light_direct(p, n, id, seed, m) +
         emitters_light_direct(p, n, id, seed, m, true, known);
}

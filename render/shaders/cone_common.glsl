/* Cone tracing through the octree's level volumes: a line-for-line port of
 * voxgi_addon/conetrace.py::march_cones and svo_sampling.sample_levels (the numpy reference).
 *
 * Declared by the create-info (render/gpu_shaders.py): sampler `atlas` (3D RGBA16F, every
 * octree level, layout in voxgi_addon/volume_textures.py) and `params` (2D RGBA32F, one row
 * per texel along x, layout in voxgi_addon/trace_params.py).
 * Row numbers ROW_* come in as defines from voxgi_addon/volume_textures.py.
 */

vec4 param(int row) { return texelFetch(params, ivec2(row, 0), 0); }

/* The per-update numbers used at every sample, read once per invocation (load_params). */
vec4 g_root;
vec4 g_shape;
vec4 g_settings0;
vec4 g_settings3;  /* radiance_detail, transmittance_exponent */
bool g_anisotropic;
vec4 g_atlas;
vec4 g_levels[MAX_LEVELS];
float g_slabs[MAX_LEVELS];
vec4 g_cascades[MAX_CASCADES];

void load_params()
{
  g_root = param(ROW_ROOT);
  g_shape = param(ROW_SHAPE);
  g_settings0 = param(ROW_SETTINGS);
  g_settings3 = param(ROW_SETTINGS + 3);
  g_anisotropic = param(ROW_SETTINGS + 2).x > 0.5;
  g_atlas = param(ROW_ATLAS);
  for (int i = 0; i < MAX_LEVELS; i++) {
    g_levels[i] = param(ROW_LEVELS + i);
    g_slabs[i] = param(ROW_SLABS + i).x;
  }
  for (int i = 0; i < MAX_CASCADES; i++) {
    g_cascades[i] = param(ROW_CASCADES + i);
  }
}

int finest_level_at(vec3 p)
{
  vec4 root = g_root;
  vec4 shape = g_shape;
  vec3 u = (p - root.xyz) / root.w;
  float u_min = min(min(u.x, u.y), u.z);
  float u_max = max(max(u.x, u.y), u.z);
  int best = -1;
  for (int i = 0; i < int(shape.z); i++) {
    vec4 c = g_cascades[i];
    float scale = exp2(c.x);
    if (u_min >= c.y / scale && u_max < (c.y + shape.y) / scale) {
      best = max(best, int(c.x));
    }
  }
  return best;
}

float local_voxel_size(vec3 p)
{
  vec4 shape = g_shape;
  float finest = float(max(finest_level_at(p), 0));
  return shape.w * exp2(shape.x - finest);
}

/* One level's sample for a cone along dir: premultiplied colour for the extinction alpha
 * (rgb), extinction alpha (.w) and the blended alpha (returned in blended). The colour weighs
 * each face by its share |d_a|·τ_a of the optical depth (svo_sampling.trilinear_directional). */
vec4 sample_level_at(int level, vec3 p, vec3 dir, bool anisotropic, float zbase,
                     out float blended)
{
  vec4 win = g_levels[level];
  float node = g_root.w / exp2(float(level));
  float pad = g_atlas.x;
  /* Texel coordinates within the level's blocks, kept inside their zero border. */
  vec3 t = clamp((p - g_root.xyz) / node - win.xyz + 1.0, 0.0, win.w + 2.0);
  vec3 scale = vec3(1.0 / (7.0 * pad), 1.0 / pad, 1.0 / g_atlas.y);
  t.z += g_slabs[level] + zbase;
  if (!anisotropic) {
    vec4 v = textureLod(atlas, (t + vec3(6.0 * pad, 0.0, 0.0)) * scale, 0.0);
    blended = v.w;
    return v;
  }
  vec3 colour = vec3(0.0);
  float optical_depth = 0.0;
  float blend = 0.0;
  float transmit = 1.0;
  for (int a = 0; a < 3; a++) {
    float face = float(2 * a + (dir[a] > 0.0 ? 1 : 0));
    vec4 v = textureLod(atlas, (t + vec3(face * pad, 0.0, 0.0)) * scale, 0.0);
    float along = abs(dir[a]);
    float tau = -log(1.0 - clamp(v.w, 0.0, TAU_ALPHA_CAP));
    float tau_per_alpha = v.w > 1e-4 ? tau / v.w : 1.0 + 0.5 * max(v.w, 0.0);
    colour += along * tau_per_alpha * v.rgb;
    optical_depth += along * tau;
    blend += dir[a] * dir[a] * v.w;
    transmit *= pow(clamp(1.0 - v.w, 0.0, 1.0), along);
  }
  blended = blend;
  float alpha = 1.0 - transmit;
  return vec4(colour * (alpha / max(optical_depth, 1e-12)), alpha);
}

vec4 sample_level(int level, vec3 p, vec3 dir, bool anisotropic, out float blended)
{
  return sample_level_at(level, p, dir, anisotropic, 0.0, blended);
}

/* Light cones of Diffuse Indirect set this: their samples' colour loses the emission octree's
 * (the atlas' copy of VoxelOctree.emission from z = g_atlas.z on, when g_atlas.z > 0), as
 * conetrace.march_cones' subtract does. */
bool g_subtract_emission = false;

/* Levels floor(level) and floor(level) + 1 blended linearly (svo_sampling.sample_levels),
 * from the slabs starting at zbase. */
vec4 sample_volume_at(float level, vec3 p, vec3 dir, bool anisotropic, float zbase,
                      out float blended)
{
  int depth = int(g_shape.x);
  float lev = clamp(level, 0.0, float(depth));
  int lo = int(floor(lev));
  float t = lev - float(lo);
  vec4 v = sample_level_at(lo, p, dir, anisotropic, zbase, blended);
  if (t > 0.0) {
    float blended_hi;
    vec4 hi = sample_level_at(min(lo + 1, depth), p, dir, anisotropic, zbase, blended_hi);
    v = mix(v, hi, t);
    blended = mix(blended, blended_hi, t);
  }
  return v;
}

vec4 sample_volume(float level, vec3 p, vec3 dir, bool anisotropic, out float blended)
{
  vec4 v = sample_volume_at(level, p, dir, anisotropic, 0.0, blended);
  if (g_subtract_emission && g_atlas.z > 0.0 && v.w > 1e-6) {  /* emission is premultiplied */
    float unused;
    vec4 e = sample_volume_at(level, p, dir, anisotropic, g_atlas.z, unused);
    v.rgb = max(v.rgb - e.rgb, vec3(0.0));
  }
  return v;
}

/* ---- The world seen by cones that leave the voxels (conetrace.WorldMips), packed after the
 * parameter rows by volume_textures.world_mip_rows: the last texel = (count, 0, 0, -1), the
 * count texels before it = (first texel, rows H) of each map (W = 2H), finest first. */
int g_world_header = -1;

void load_world()
{
  int width = textureSize(params, 0).x;
  g_world_header = param(width - 1).w < -0.5 ? width - 1 : -1;
}

vec3 world_bilinear(int first, int rows, vec3 d)
{
  int cols = 2 * rows;
  float len = length(d);
  float z = len > 0.0 ? d.z / len : 0.0;
  float el = asin(clamp(z, -1.0, 1.0));
  float phi = (d.x == 0.0 && d.y == 0.0) ? 0.0 : atan(d.y, d.x);
  float y = clamp((1.5707963267948966 - el) * float(rows) / 3.141592653589793 - 0.5, 0.0,
                  float(rows) - 1.0);
  float x = (phi + 3.141592653589793) * float(cols) / 6.283185307179586 - 0.5;
  int y0 = min(int(floor(y)), rows - 1);
  int y1 = min(y0 + 1, rows - 1);
  float fy = y - float(y0);
  float x0f = floor(x);
  float fx = x - x0f;
  int x0 = ((int(x0f) % cols) + cols) % cols;
  int x1 = (x0 + 1) % cols;
  vec3 top = param(first + y0 * cols + x0).rgb * (1.0 - fx) + param(first + y0 * cols + x1).rgb * fx;
  vec3 bottom = param(first + y1 * cols + x0).rgb * (1.0 - fx) + param(first + y1 * cols + x1).rgb * fx;
  return top * (1.0 - fy) + bottom * fy;
}

/* Radiance of the world along unit d for a cone of half-angle half_angle (radians): the map
 * whose rows are as wide as the cone (conetrace.world_mip_level), bilinear, the two nearest
 * blended; 0 without a world. */
vec3 world_radiance(vec3 d, float half_angle)
{
  if (g_world_header < 0) {
    return vec3(0.0);
  }
  int count = int(param(g_world_header).x);
  vec4 base = param(g_world_header - count);
  float width = 2.0 * max(half_angle, 1e-6);
  float level = clamp(log2(base.y * width / 3.141592653589793), 0.0, float(count - 1));
  int lo = int(floor(level));
  float t = level - float(lo);
  vec4 mip = param(g_world_header - count + lo);
  vec3 value = world_bilinear(int(mip.x), int(mip.y), d);
  if (lo + 1 < count) {
    vec4 upper = param(g_world_header - count + lo + 1);
    value = value * (1.0 - t) + world_bilinear(int(upper.x), int(upper.y), d) * t;
  }
  return value;
}

/* Light cones that only need their transmittance (the world's visibility) skip the finer
 * level's colour. */
bool g_want_colour = true;

/* Scale alpha by opacity_scale (clamped to 1), premultiplied colour alike. */
vec4 scale_opacity(vec4 v, float scale)
{
  if (scale == 1.0) {
    return v;
  }
  float scaled = min(v.w * scale, 1.0);
  return vec4(v.rgb * (scaled / max(v.w, 1e-12)), scaled);
}

/* March one cone front to back (conetrace.march_cones). Two occlusion channels share the
 * samples: the light channel (extinction alpha, to light_distance, with radiance and the
 * settings' falloff) and the occlusion channel (blended alpha, to occlusion_distance, with
 * occlusion_falloff). A distance of 0 switches a channel off. When clamp_surface, a sample
 * never reads nodes wider than 2/3 of its height above the surface (normal sn, height base). */
void march(vec3 origin, vec3 dir, float tan_half, float local, float light_distance,
           float occlusion_distance, float occlusion_falloff, bool clamp_surface, vec3 sn,
           float base, out vec3 radiance, out float alpha_light, out float alpha_occlusion)
{
  vec4 s0 = g_settings0;  /* sample_factor, falloff, -, opacity_scale */
  float depth = g_shape.x;
  float leaf = g_shape.w;
  bool anisotropic = g_anisotropic;
  radiance = vec3(0.0);
  alpha_light = 0.0;
  alpha_occlusion = 0.0;
  float d = 0.0;
  bool on_light = d < light_distance;
  bool on_occlusion = d < occlusion_distance;
  float rise = dot(dir, sn);
  for (int guard = 0; guard < 4096 && (on_light || on_occlusion); guard++) {
    float diameter = 2.0 * tan_half * d;
    float widest = 0.0;
    if (clamp_surface) {
      widest = (2.0 / 3.0) * max(base + d * rise, 1e-9);
      diameter = min(diameter, widest);
    }
    diameter = max(diameter, local);
    vec3 p = origin + dir * d;
    float level = depth - log2(diameter / leaf);
    if (clamp_surface) {
      level = max(level, ceil(depth - log2(widest / leaf) - 1e-5));
    }
    float finest = float(finest_level_at(p));
    level = min(max(level, 0.0), finest);
    level = clamp(level, 0.0, depth);
    float blended;
    vec4 v = sample_volume(level, p, dir, anisotropic, blended);
    /* Light: the colour from radiance_detail levels finer where that level holds the
     * occluders this one sees (conetrace.march_cones). */
    float fine = min(level + g_settings3.x, finest);
    if (on_light && g_want_colour && v.w > 1e-6 && fine > level) {
      float unused;
      vec4 f = sample_volume(fine, p, dir, anisotropic, unused);
      float m = min(f.w / v.w, 1.0);
      v.rgb = m * (v.w / max(f.w, 1e-12)) * f.rgb + (1.0 - m) * v.rgb;
    }
    v = scale_opacity(v, s0.w);
    blended = min(blended * s0.w, 1.0);
    float step_length = diameter * s0.x;
    float node = leaf * exp2(depth - level);
    float exponent = step_length / node;
    float a_light = 1.0 - pow(clamp(1.0 - v.w, 0.0, 1.0), exponent * g_settings3.y);
    float a_occ = 1.0 - pow(clamp(1.0 - blended, 0.0, 1.0), exponent);
    if (on_light) {
      float weight = (1.0 - alpha_light) / (1.0 + s0.y * d);
      radiance += weight * v.rgb;
      alpha_light += weight * a_light;
    }
    if (on_occlusion) {
      alpha_occlusion += (1.0 - alpha_occlusion) / (1.0 + occlusion_falloff * d) * a_occ;
    }
    d += step_length;
    on_light = on_light && d < light_distance && alpha_light < 0.999;
    on_occlusion = on_occlusion && d < occlusion_distance && alpha_occlusion < 0.999;
  }
  alpha_light = clamp(alpha_light, 0.0, 1.0);
  alpha_occlusion = clamp(alpha_occlusion, 0.0, 1.0);
}

/* Two unit vectors orthogonal to the unit normal n (Duff et al. 2017), as conetrace.py. */
void tangent_frame(vec3 n, out vec3 t, out vec3 s)
{
  float sgn = n.z >= 0.0 ? 1.0 : -1.0;
  float a = -1.0 / (sgn + n.z);
  float b = n.x * n.y * a;
  t = vec3(1.0 + sgn * n.x * n.x * a, sgn * b, -sgn * n.x);
  s = vec3(b, sgn + n.y * n.y * a, -n.y);
}


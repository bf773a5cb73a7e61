/* Materials per texel: the port of voxgi_addon/scene/textures.py (sample_texture): a
 * material's Base Color texture at a surface UV, through its UV transform (Mapping nodes),
 * Linear (bilinear) or Closest within a mip level, Repeat / Extend / Clip, trilinear between
 * levels. Samplers: texture_table (TEXTURE_TEXELS texels per texture, one row each:
 * textures.pack_atlas), texture_atlas (every level of every texture, RGBA16F). The wrap is
 * done here on texel indices (an atlas cannot wrap), as numpy does it. The atlas' A channel
 * is the textures' alpha (1 without one): cut-outs (bvh_cutout_counts, at the end). */

/* textures.srgb_to_linear: encoded sRGB -> linear. */
vec3 texture_srgb_decode(vec3 c)
{
  return mix(pow((max(c, vec3(0.04045)) + 0.055) / 1.055, vec3(2.4)), c / 12.92,
             vec3(lessThanEqual(c, vec3(0.04045))));
}

int texture_wrap(int x, int size)
{
  return x - size * int(floor(float(x) / float(size)));
}

vec4 texture_fetch4(vec4 rect, int x, int y, int extension)
{
  int w = int(rect.z + 0.5);
  int h = int(rect.w + 0.5);
  if (extension == 0) {
    x = texture_wrap(x, w);
    y = texture_wrap(y, h);
  }
  else {
    if (extension == 2 && (x < 0 || x >= w || y < 0 || y >= h)) {
      return vec4(0.0);
    }
    x = clamp(x, 0, w - 1);
    y = clamp(y, 0, h - 1);
  }
  return texelFetch(texture_atlas, ivec2(int(rect.x + 0.5) + x, int(rect.y + 0.5) + y), 0);
}

vec4 texture_level4_raw(int slot, int level, vec2 st, int interpolation, int extension)
{
  vec4 rect = texelFetch(texture_table, ivec2(3 + level, slot), 0);
  float x = st.x * rect.z;
  float y = st.y * rect.w;
  if (interpolation == 1) {
    return texture_fetch4(rect, int(floor(x)), int(floor(y)), extension);
  }
  x -= 0.5;
  y -= 0.5;
  float x0 = floor(x);
  float y0 = floor(y);
  float fx = x - x0;
  float fy = y - y0;
  int ix = int(x0);
  int iy = int(y0);
  vec4 bottom = texture_fetch4(rect, ix, iy, extension) * (1.0 - fx) +
                texture_fetch4(rect, ix + 1, iy, extension) * fx;
  vec4 top = texture_fetch4(rect, ix, iy + 1, extension) * (1.0 - fx) +
             texture_fetch4(rect, ix + 1, iy + 1, extension) * fx;
  return bottom * (1.0 - fy) + top * fy;
}

/* One level's four channels; level 0 of a byte sRGB image holds encoded colour, blended and
 * then decoded as Cycles does (textures.encoded: the table's texel 2 .y). */
vec4 texture_level4(int slot, int level, vec2 st, int interpolation, int extension)
{
  vec4 value = texture_level4_raw(slot, level, st, interpolation, extension);
  if (level == 0 && texelFetch(texture_table, ivec2(2, slot), 0).y > 0.5) {
    value.rgb = texture_srgb_decode(value.rgb);
  }
  return value;
}

vec3 texture_level(int slot, int level, vec2 st, int interpolation, int extension)
{
  return texture_level4(slot, level, st, interpolation, extension).rgb;
}

/* Texture `slot` at surface UV `uv`, level of detail `lod` (log2 of the footprint in
 * level-0 texels). */
vec3 surface_texture(int slot, vec2 uv, float lod)
{
  vec4 a = texelFetch(texture_table, ivec2(0, slot), 0);
  vec4 b = texelFetch(texture_table, ivec2(1, slot), 0);
  int extension = int(texelFetch(texture_table, ivec2(2, slot), 0).x + 0.5);
  vec2 st = vec2(a.x * uv.x + a.y * uv.y + a.z, b.x * uv.x + b.y * uv.y + b.z);
  int levels = int(a.w + 0.5);
  int interpolation = int(b.w + 0.5);
  lod = clamp(lod, 0.0, float(levels - 1));
  int l0 = int(floor(lod));
  float f = lod - float(l0);
  vec3 value = texture_level(slot, l0, st, interpolation, extension);
  if (l0 + 1 < levels) {
    value = value * (1.0 - f) + texture_level(slot, l0 + 1, st, interpolation, extension) * f;
  }
  return value;
}

/* textures.pack_emission: an RGB emission (clamped to [0, 65280]) as one float >= 2 (bits
 * 0x40000000 + payload, payload = a shared exponent E (5 bits, 2^(E - 15)) and three 8-bit
 * mantissas; 0 for no emission): the G-buffer's base.w, which kernels testing w > 0.5 for a
 * textured Base Color read as before. unpack_emission inverts it. */
float pack_emission(vec3 e)
{
  e = clamp(e, vec3(0.0), vec3(65280.0));
  float m = max(max(e.r, e.g), e.b);
  uint payload = 0u;
  if (m >= exp2(-15.0)) {
    int x = clamp(int(floor(log2(m))) + 1, -14, 16);
    uvec3 c = uvec3(clamp(floor(e * exp2(8.0 - float(x)) + 0.5), vec3(0.0), vec3(255.0)));
    payload = (uint(x + 15) << 24) | (c.r << 16) | (c.g << 8) | c.b;
  }
  return uintBitsToFloat(0x40000000u + payload);
}

vec3 unpack_emission(float w)
{
  uint bits = floatBitsToUint(w) - 0x40000000u;
  return vec3(uvec3(bits >> 16, bits >> 8, bits) & uvec3(255u)) *
         exp2(float(int(bits >> 24) - 15) - 8.0);
}

/* Texture `slot`'s four channels at surface UV `uv`, level 0 (textures.sample_rgba). */
vec4 surface_texel(int slot, vec2 uv)
{
  vec4 a = texelFetch(texture_table, ivec2(0, slot), 0);
  vec4 b = texelFetch(texture_table, ivec2(1, slot), 0);
  int extension = int(texelFetch(texture_table, ivec2(2, slot), 0).x + 0.5);
  vec2 st = vec2(a.x * uv.x + a.y * uv.y + a.z, b.x * uv.x + b.y * uv.y + b.z);
  return texture_level4(slot, 0, st, int(b.w + 0.5), extension);
}

/* Texture `slot`'s alpha (its 4th channel) at surface UV `uv`, level 0. */
float surface_alpha(int slot, vec2 uv)
{
  return surface_texel(slot, uv).a;
}

/* textures.cutout_random: the hash of a ray's origin and direction in steps of
 * 1 / CUTOUT_QUANTUM and a triangle index, uniform in [0, 1) (pcg_hash: sampling.glsl). */
float cutout_random(vec3 o, vec3 d, int triangle)
{
  ivec3 qo = ivec3(floor(o * 4096.0));
  ivec3 qd = ivec3(floor(d * 4096.0));
  uint h = pcg_hash(uint(triangle));
  h = pcg_hash(h ^ uint(qo.x));
  h = pcg_hash(h ^ uint(qo.y));
  h = pcg_hash(h ^ uint(qo.z));
  h = pcg_hash(h ^ uint(qd.x));
  h = pcg_hash(h ^ uint(qd.y));
  h = pcg_hash(h ^ uint(qd.z));
  return unit_float(h);
}

/* textures.cutout_hits: does the ray (o, d)'s hit at barycentrics uv of cut-out triangle
 * `triangle` (a SceneTriangles index) count? The triangle's texels in texture_table's rows
 * after the textures' (gpu_scene._update_textures): (uv0, uv1), (uv2, alpha texture, alpha
 * value); the Alpha is the texture's 4th channel where there is one, else the value. */
#ifdef BVH_CUTOUTS
bool bvh_cutout_counts(int triangle, vec2 uv, vec3 o, vec3 d)
{
  int k = 2 * triangle;
  int row = int(texelFetch(texture_table, ivec2(BVH_WIDTH - 1, 0), 0).x + 0.5);
  vec4 c2 = texelFetch(texture_table,
                       ivec2((k + 1) & (BVH_WIDTH - 1), row + ((k + 1) >> BVH_WIDTH_LOG2)), 0);
  float alpha = c2.w;
  int slot = int(floor(c2.z + 0.5));
  if (slot >= 0) {
    vec4 c01 = texelFetch(texture_table,
                          ivec2(k & (BVH_WIDTH - 1), row + (k >> BVH_WIDTH_LOG2)), 0);
    vec2 at = (1.0 - uv.x - uv.y) * c01.xy + uv.x * c01.zw + uv.y * c2.xy;
    alpha = clamp(surface_alpha(slot, at), 0.0, 1.0);
  }
  return cutout_random(o, d, triangle) < alpha;
}
#endif

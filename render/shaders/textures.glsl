/* Materials per texel: the port of voxgi_addon/scene/textures.py (sample_texture): a
 * material's Base Color texture at a surface UV, through its UV transform (Mapping nodes),
 * Linear (bilinear) or Closest within a mip level, Repeat / Extend / Clip, trilinear between
 * levels. Samplers: texture_table (TEXTURE_TEXELS texels per texture, one row each:
 * textures.pack_atlas), texture_atlas (every level of every texture, RGBA16F). The wrap is
 * done here on texel indices (an atlas cannot wrap), as numpy does it. */

int texture_wrap(int x, int size)
{
  return x - size * int(floor(float(x) / float(size)));
}

vec3 texture_fetch(vec4 rect, int x, int y, int extension)
{
  int w = int(rect.z + 0.5);
  int h = int(rect.w + 0.5);
  if (extension == 0) {
    x = texture_wrap(x, w);
    y = texture_wrap(y, h);
  }
  else {
    if (extension == 2 && (x < 0 || x >= w || y < 0 || y >= h)) {
      return vec3(0.0);
    }
    x = clamp(x, 0, w - 1);
    y = clamp(y, 0, h - 1);
  }
  return texelFetch(texture_atlas, ivec2(int(rect.x + 0.5) + x, int(rect.y + 0.5) + y), 0).rgb;
}

vec3 texture_level(int slot, int level, vec2 st, int interpolation, int extension)
{
  vec4 rect = texelFetch(texture_table, ivec2(3 + level, slot), 0);
  float x = st.x * rect.z;
  float y = st.y * rect.w;
  if (interpolation == 1) {
    return texture_fetch(rect, int(floor(x)), int(floor(y)), extension);
  }
  x -= 0.5;
  y -= 0.5;
  float x0 = floor(x);
  float y0 = floor(y);
  float fx = x - x0;
  float fy = y - y0;
  int ix = int(x0);
  int iy = int(y0);
  vec3 bottom = texture_fetch(rect, ix, iy, extension) * (1.0 - fx) +
                texture_fetch(rect, ix + 1, iy, extension) * fx;
  vec3 top = texture_fetch(rect, ix, iy + 1, extension) * (1.0 - fx) +
             texture_fetch(rect, ix + 1, iy + 1, extension) * fx;
  return bottom * (1.0 - fy) + top * fy;
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

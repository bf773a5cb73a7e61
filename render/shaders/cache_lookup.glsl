/* The multi-bounce radiance cache's indirect light (E/π) at `x` for unit normal `n`
 * (voxgi_addon/gi/radiance_cache.py lookup; texels: radiance_cache.cache_texels): per axis the
 * face n faces, trilinear over the voxels of the finest grid holding `x` that hold that face
 * (texel .a), the axes blended by n² over those some neighbour holds (else the next coarser
 * grid holding `x`); 0 outside every grid and for the 1 × 1 blank texture (no cache).
 * A texture with two parts (header .z = 1) also holds the next iteration, which the glossy
 * gather reads (radiance_cache.glossy_view): its main() sets cache_part = 1. A corner's voxel
 * is found through the grid's id rows (-1: none there), its faces among the compact faces.
 * An axis whose n² is under CACHE_AXIS_BLEND weighs nothing and its faces are not fetched: a
 * wall's or a floor's hit reads 8 texels, not 24 (docs/gi_pipeline.md "Multi-bounce radiance
 * cache", "What the cache costs, measured again"). */
#define CACHE_AXIS_BLEND 1e-6
int cache_part = 0;

vec3 cache_indirect(vec3 x, vec3 n)
{
  ivec2 size = textureSize(radiance_cache, 0);
  vec4 info = texelFetch(radiance_cache, ivec2(size.x - 1, 0), 0);
  int res = int(info.x + 0.5);
  int count = int(info.y + 0.5);
  /* the faces' first texel: part 1's after all of part 0's (V voxels × 6 faces) */
  int part = (cache_part == 1 && info.z > 0.5) ? int(info.w + 0.5) * 6 : 0;
  int first_row = 1 + count * res;
  ivec3 face = ivec3(n.x < 0.0 ? 1 : 0, n.y < 0.0 ? 3 : 2, n.z < 0.0 ? 5 : 4);
  vec3 blend = n * n;
  bvec3 axes = greaterThanEqual(blend, vec3(CACHE_AXIS_BLEND));
  blend = mix(vec3(0.0), blend, axes);
  for (int g = 0; g < count; g++) {
    vec4 grid = texelFetch(radiance_cache, ivec2(g, 0), 0);
    vec3 at = (x - grid.xyz) / grid.w;
    if (any(lessThan(at, vec3(0.0))) || any(greaterThanEqual(at, vec3(float(res))))) {
      continue;
    }
    vec3 gg = at - 0.5;
    ivec3 base = ivec3(floor(gg));
    vec3 f = gg - vec3(base);
    vec3 tx = vec3(0.0), ty = vec3(0.0), tz = vec3(0.0);
    vec3 weight = vec3(0.0);
    for (int corner = 0; corner < 8; corner++) {
      ivec3 o = ivec3((corner >> 2) & 1, (corner >> 1) & 1, corner & 1);
      ivec3 cell = base + o;
      if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, ivec3(res)))) {
        continue;
      }
      float id = texelFetch(radiance_cache, ivec2(cell.x + cell.y * res, 1 + g * res + cell.z),
                            0).x;
      if (id < -0.5) {
        continue; /* no voxel of the grid there */
      }
      int first = part + int(id + 0.5) * 6;
      ivec3 t = ivec3(first) + face;
      vec4 fx = axes.x ? texelFetch(radiance_cache, ivec2(t.x % size.x, first_row + t.x / size.x),
                                    0) : vec4(0.0);
      vec4 fy = axes.y ? texelFetch(radiance_cache, ivec2(t.y % size.x, first_row + t.y / size.x),
                                    0) : vec4(0.0);
      vec4 fz = axes.z ? texelFetch(radiance_cache, ivec2(t.z % size.x, first_row + t.z / size.x),
                                    0) : vec4(0.0);
      vec3 wv = mix(1.0 - f, f, vec3(o));
      float w = wv.x * wv.y * wv.z;
      vec3 held = w * vec3(fx.w > 0.5 ? 1.0 : 0.0, fy.w > 0.5 ? 1.0 : 0.0, fz.w > 0.5 ? 1.0 : 0.0);
      tx += held.x * fx.rgb;
      ty += held.y * fy.rgb;
      tz += held.z * fz.rgb;
      weight += held;
    }
    vec3 share = vec3(weight.x > 1e-6 ? blend.x : 0.0, weight.y > 1e-6 ? blend.y : 0.0,
                      weight.z > 1e-6 ? blend.z : 0.0);
    float norm = share.x + share.y + share.z;
    if (norm <= 1e-6) {
      continue; /* no voxel here holds a face n faces: the next coarser grid */
    }
    vec3 safe = max(weight, vec3(1e-6));
    return (share.x * tx / safe.x + share.y * ty / safe.y + share.z * tz / safe.z) / norm;
  }
  return vec3(0.0);
}

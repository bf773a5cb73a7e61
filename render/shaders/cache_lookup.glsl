/* The multi-bounce radiance cache's indirect light (E/π, .rgb) at `x` for unit normal `n`, and
 * (.a) its faces' one-more-bounce ratio blended alike, each face's also weighted by its light
 * (the first part's texels' .a − 1: radiance_cache.one_more_bounce; 0 where the texture has
 * none)
 * (voxgi_addon/gi/radiance_cache.py lookup; texels: radiance_cache.cache_texels): per axis the
 * face n faces, trilinear over the voxels of the finest grid holding `x` that hold that face
 * (texel .a), the axes blended by n² over those some neighbour holds (else the next coarser
 * grid holding `x`); 0 outside every grid and for the 1 × 1 blank texture (no cache).
 * A texture with two parts also holds the next iteration (from which the
 * relaxation's last pass makes part 0's .a) and, parts 2 …, the earlier iterations, latest
 * first (the rays followed past near hits: bvh_shade.glsl); lookups read part `part`. A
 * corner's voxel
 * is found through the grid's id rows (-1: none there), its faces among the compact faces.
 * An axis whose n² is under CACHE_AXIS_BLEND weighs nothing and its faces are not fetched: a
 * wall's or a floor's hit reads 8 texels, not 24 (docs/gi_pipeline.md "Multi-bounce radiance
 * cache", "What the cache costs, measured again"). */
#define CACHE_AXIS_BLEND 1e-6
/* A neighbour's face is read only where its surface lies at most this many voxels behind the
 * point's tangent plane, unless none of that axis' held faces does (radiance_cache.py
 * PLANE_TOLERANCE, _in_front; docs/gi_pipeline.md "Faces behind the point"). */
#define CACHE_PLANE_TOLERANCE 0.25
#define CACHE_PLANE_STEPS 63.5

/* The planes of the faces `face` (one per axis) of a voxel whose id texel is `id`: each face's
 * ray origin along its axis, in voxels from the voxel's centre (.z: faces +x, −x, +y; .w: −y,
 * +z, −z, 7 bits each: radiance_cache.plane_codes). */
vec3 cache_planes(vec4 id, ivec3 face)
{
  ivec2 codes = ivec2(id.zw + 0.5);
  vec3 q;
  for (int a = 0; a < 3; a++) {
    int f = face[a];
    int code = f < 3 ? codes.x : codes.y;
    q[a] = float((code >> (7 * (f % 3))) & 127);
  }
  return q / CACHE_PLANE_STEPS - 1.0;
}

/* Per axis: does the face `face` of voxel `cell` (id texel `id`) of the grid at `grid` (origin,
 * cell size) lie in front of the tangent plane at x with normal n, within the tolerance
 * (radiance_cache._in_front)? */
bvec3 cache_in_front(vec4 grid, ivec3 cell, vec4 id, ivec3 face, vec3 x, vec3 n)
{
  vec3 centre = grid.xyz + (vec3(cell) + 0.5) * grid.w;
  float base = dot(centre - x, n);
  return greaterThanEqual(vec3(base) + grid.w * cache_planes(id, face) * n,
                          vec3(-CACHE_PLANE_TOLERANCE * grid.w));
}

/* Where `x` lies in grid g of the cache (res cells a side; its origin and cell size in header
 * texel (g, 0)): false outside it, else the lower corner `base` of the 2 × 2 × 2 voxels around
 * x and its trilinear fractions `f` (cache_indirect and cache_pick walk the grids alike). */
bool cache_grid_cell(vec3 x, int g, int res, out ivec3 base, out vec3 f)
{
  vec4 grid = texelFetch(radiance_cache, ivec2(g, 0), 0);
  vec3 at = (x - grid.xyz) / grid.w;
  base = ivec3(0);
  f = vec3(0.0);
  if (any(lessThan(at, vec3(0.0))) || any(greaterThanEqual(at, vec3(float(res))))) {
    return false;
  }
  vec3 gg = at - 0.5;
  base = ivec3(floor(gg));
  f = gg - vec3(base);
  return true;
}

/* The iterations the cache's first part holds (Bounces − 1), and whether it has the ahead and
 * earlier parts (header .z = 2 × iterations + 1 with them: radiance_cache.cache_texels). */
int cache_iterations()
{
  return int(texelFetch(radiance_cache, ivec2(textureSize(radiance_cache, 0).x - 1, 0), 0).z +
             0.5) >> 1;
}

bool cache_has_levels()
{
  return (int(texelFetch(radiance_cache, ivec2(textureSize(radiance_cache, 0).x - 1, 0), 0).z +
              0.5) & 1) == 1;
}

/* The cell size of the finest grid of the cache holding `x`, 0 outside every grid
 * (radiance_cache.cell_size). */
float cache_cell_size(vec3 x)
{
  vec4 info = texelFetch(radiance_cache, ivec2(textureSize(radiance_cache, 0).x - 1, 0), 0);
  int res = int(info.x + 0.5);
  int count = int(info.y + 0.5);
  for (int g = 0; g < count; g++) {
    ivec3 base;
    vec3 f;
    if (cache_grid_cell(x, g, res, base, f)) {
      return texelFetch(radiance_cache, ivec2(g, 0), 0).w;
    }
  }
  return 0.0;
}

vec4 cache_indirect(vec3 x, vec3 n, int part)
{
  ivec2 size = textureSize(radiance_cache, 0);
  vec4 info = texelFetch(radiance_cache, ivec2(size.x - 1, 0), 0);
  int res = int(info.x + 0.5);
  int count = int(info.y + 0.5);
  int first_row = 1 + count * res;
  ivec3 face = ivec3(n.x < 0.0 ? 1 : 0, n.y < 0.0 ? 3 : 2, n.z < 0.0 ? 5 : 4);
  vec3 blend = n * n;
  bvec3 axes = greaterThanEqual(blend, vec3(CACHE_AXIS_BLEND));
  blend = mix(vec3(0.0), blend, axes);
  for (int g = 0; g < count; g++) {
    ivec3 base;
    vec3 f;
    if (!cache_grid_cell(x, g, res, base, f)) {
      continue;
    }
    vec4 grid = texelFetch(radiance_cache, ivec2(g, 0), 0);
    /* per axis over the faces in front (cache_in_front) and, where none is, over all held */
    vec3 tx = vec3(0.0), ty = vec3(0.0), tz = vec3(0.0);
    vec3 ax = vec3(0.0), ay = vec3(0.0), az = vec3(0.0);
    /* per axis: Σ weight · light · (.a − 1), the faces' one-more-bounce ratio weighted by their
     * light too (radiance_cache.lookup), and Σ weight · light */
    vec3 more = vec3(0.0);
    vec3 more_all = vec3(0.0);
    vec3 lit = vec3(0.0), lit_all = vec3(0.0);
    vec3 weight = vec3(0.0), weight_all = vec3(0.0);
    for (int corner = 0; corner < 8; corner++) {
      ivec3 o = ivec3((corner >> 2) & 1, (corner >> 1) & 1, corner & 1);
      ivec3 cell = base + o;
      if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, ivec3(res)))) {
        continue;
      }
      vec4 id_texel = texelFetch(radiance_cache,
                                 ivec2(cell.x + cell.y * res, 1 + g * res + cell.z), 0);
      float id = id_texel.x;
      if (id < -0.5) {
        continue; /* no voxel of the grid there */
      }
      /* part `part`'s faces: each part follows all of the previous one's (info.w voxels) */
      int first = (int(id + 0.5) + part * int(info.w + 0.5)) * 6;
      ivec3 t = ivec3(first) + face;
      vec4 fx = axes.x ? texelFetch(radiance_cache, ivec2(t.x % size.x, first_row + t.x / size.x),
                                    0) : vec4(0.0);
      vec4 fy = axes.y ? texelFetch(radiance_cache, ivec2(t.y % size.x, first_row + t.y / size.x),
                                    0) : vec4(0.0);
      vec4 fz = axes.z ? texelFetch(radiance_cache, ivec2(t.z % size.x, first_row + t.z / size.x),
                                    0) : vec4(0.0);
      vec3 wv = mix(1.0 - f, f, vec3(o));
      float w = wv.x * wv.y * wv.z;
      vec3 loose = w * vec3(fx.w > 0.5 ? 1.0 : 0.0, fy.w > 0.5 ? 1.0 : 0.0, fz.w > 0.5 ? 1.0 : 0.0);
      vec3 held = mix(vec3(0.0), loose, cache_in_front(grid, cell, id_texel, face, x, n));
      tx += held.x * fx.rgb;
      ty += held.y * fy.rgb;
      tz += held.z * fz.rgb;
      ax += loose.x * fx.rgb;
      ay += loose.y * fy.rgb;
      az += loose.z * fz.rgb;
      vec3 light = max(vec3(dot(fx.rgb, vec3(1.0)), dot(fy.rgb, vec3(1.0)),
                            dot(fz.rgb, vec3(1.0))), vec3(0.0));
      more += held * light * (vec3(fx.w, fy.w, fz.w) - 1.0);
      more_all += loose * light * (vec3(fx.w, fy.w, fz.w) - 1.0);
      lit += held * light;
      lit_all += loose * light;
      weight += held;
      weight_all += loose;
    }
    bvec3 strict = greaterThan(weight, vec3(1e-6));
    tx = strict.x ? tx : ax;
    ty = strict.y ? ty : ay;
    tz = strict.z ? tz : az;
    more = mix(more_all, more, strict);
    lit = mix(lit_all, lit, strict);
    weight = mix(weight_all, weight, strict);
    vec3 share = vec3(weight.x > 1e-6 ? blend.x : 0.0, weight.y > 1e-6 ? blend.y : 0.0,
                      weight.z > 1e-6 ? blend.z : 0.0);
    float norm = share.x + share.y + share.z;
    if (norm <= 1e-6) {
      continue; /* no voxel here holds a face n faces: the next coarser grid */
    }
    vec3 safe = max(weight, vec3(1e-6));
    return vec4(share.x * tx / safe.x + share.y * ty / safe.y + share.z * tz / safe.z,
                dot(share, more / safe) / max(dot(share, lit / safe), 1e-30) * norm) / norm;
  }
  return vec4(0.0);
}

/* Corner `corner` of grid g's trilinear neighbourhood at `base` (fractions f): its weight
 * times whether its voxel holds each axis' face `face` (the id row's mask .y; 0 outside the
 * grid or where it has no voxel), and in `front` per axis whether that face lies in front of
 * x's tangent plane (cache_in_front; grid: the grid's header texel). */
vec3 cache_corner_held(int corner, ivec3 base, vec3 f, int g, int res, ivec3 face, vec4 grid,
                       vec3 x, vec3 n, out bvec3 front)
{
  front = bvec3(false);
  ivec3 o = ivec3((corner >> 2) & 1, (corner >> 1) & 1, corner & 1);
  ivec3 cell = base + o;
  if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, ivec3(res)))) {
    return vec3(0.0);
  }
  vec4 id = texelFetch(radiance_cache, ivec2(cell.x + cell.y * res, 1 + g * res + cell.z), 0);
  if (id.x < -0.5) {
    return vec3(0.0); /* no voxel of the grid there */
  }
  int mask = int(id.y + 0.5);
  vec3 wv = mix(1.0 - f, f, vec3(o));
  front = cache_in_front(grid, cell, id, face, x, n);
  return (wv.x * wv.y * wv.z) * vec3(float((mask >> face.x) & 1), float((mask >> face.y) & 1),
                                     float((mask >> face.z) & 1));
}

/* The texel of one face that cache_indirect(x, n) reads, drawn by `u` in [0, 1) with the
 * lookup's own weights (voxgi_addon/gi/radiance_cache.py pick): an axis by its share of the
 * blend, then a corner voxel by its trilinear weight among those that hold the axis' face —
 * so the face's value at that texel has the lookup's expectation. Returns the face's compact
 * index (voxel id · 6 + face: texel first_row · width + it of part 0), -1 where the lookup
 * reads 0. It reads the grids' id rows only (the faces a voxel holds: .y, a mask of 6 bits),
 * no face: the radiance cache's rays pick once, where they hit (cache_paths.glsl), and each
 * relaxation (cache_relax.glsl) reads one texel per ray instead of a lookup's 8 to 24
 * (docs/gi_pipeline.md "Multi-bounce radiance cache", "Each ray picks one face"). */
float cache_pick(vec3 x, vec3 n, float u)
{
  vec4 info = texelFetch(radiance_cache, ivec2(textureSize(radiance_cache, 0).x - 1, 0), 0);
  int res = int(info.x + 0.5);
  int count = int(info.y + 0.5);
  ivec3 face = ivec3(n.x < 0.0 ? 1 : 0, n.y < 0.0 ? 3 : 2, n.z < 0.0 ? 5 : 4);
  vec3 blend = n * n;
  blend = mix(vec3(0.0), blend, greaterThanEqual(blend, vec3(CACHE_AXIS_BLEND)));
  for (int g = 0; g < count; g++) {
    ivec3 base;
    vec3 f;
    if (!cache_grid_cell(x, g, res, base, f)) {
      continue;
    }
    vec4 grid = texelFetch(radiance_cache, ivec2(g, 0), 0);
    /* per axis the faces in front, where some are (else all held: cache_indirect) */
    vec3 weight = vec3(0.0), weight_all = vec3(0.0);
    for (int corner = 0; corner < 8; corner++) {
      bvec3 front;
      vec3 held = cache_corner_held(corner, base, f, g, res, face, grid, x, n, front);
      weight += held * vec3(front);
      weight_all += held;
    }
    bvec3 strict = greaterThan(weight, vec3(1e-6));
    weight = mix(weight_all, weight, strict);
    vec3 share = vec3(weight.x > 1e-6 ? blend.x : 0.0, weight.y > 1e-6 ? blend.y : 0.0,
                      weight.z > 1e-6 ? blend.z : 0.0);
    float norm = share.x + share.y + share.z;
    if (norm <= 1e-6) {
      continue; /* no voxel here holds a face n faces: the next coarser grid */
    }
    /* the axis: the first whose running share passes u · norm (the last one that has one,
     * should rounding leave none) */
    float target = u * norm;
    int axis = share.z > 0.0 ? 2 : (share.y > 0.0 ? 1 : 0);
    if (share.x > 0.0 && target < share.x) {
      axis = 0;
    }
    else if (share.y > 0.0 && target < share.x + share.y) {
      axis = 1;
    }
    float before = axis == 0 ? 0.0 : (axis == 1 ? share.x : share.x + share.y);
    float v = clamp((target - before) / share[axis], 0.0, 1.0) * weight[axis];
    /* the corner: the last held one whose running weight before it is within v (the ids
     * fetched again: cheaper on llvmpipe than keeping them in an array) */
    int pick = -1;
    float run = 0.0;
    for (int corner = 0; corner < 8; corner++) {
      bvec3 front;
      float w = cache_corner_held(corner, base, f, g, res, face, grid, x, n, front)[axis];
      w = strict[axis] && !front[axis] ? 0.0 : w;
      if (w > 0.0) {
        if (pick < 0 || run <= v) {
          pick = corner;
        }
        run += w;
      }
    }
    ivec3 cell = base + ivec3((pick >> 2) & 1, (pick >> 1) & 1, pick & 1);
    float id = texelFetch(radiance_cache, ivec2(cell.x + cell.y * res, 1 + g * res + cell.z),
                          0).x;
    return id * 6.0 + float(face[axis]);
  }
  return -1.0;
}

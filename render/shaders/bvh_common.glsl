/* Ray casting through the threaded BVH of voxgi_addon/bvh.py (see its module doc), a port of
 * bvh.traverse.
 *
 * Samplers (2D RGBA32F, texel k at (k mod BVH_WIDTH, k div BVH_WIDTH)):
 *   bvh_nodes     : 2 texels per node, (lo.xyz, miss link), (hi.xyz, leaf code = first·16 + count
 *                   as the float of bits code + BVH_LEAF_BIAS, or -1 for an interior node);
 *                   depth-first order, node 0 the root, in 1 or BVH_ORDERS layouts of equal
 *                   rows (one per major ray direction, bvh.py ordered_layouts; one layout's
 *                   rows are padded to one more than a multiple of BVH_ORDERS).
 *   bvh_triangles : 3 texels per triangle in leaf order, (v0.xyz, material), (e1.xyz, index into
 *                   the SceneTriangles), (e2.xyz, |e1|·|e2|).
 * Defines: BVH_WIDTH_LOG2, BVH_ORDERS, BVH_SHADOW_LAYOUT, SHADOW_EPSILON (metres), DET_EPSILON
 * (relative). Hits are double-sided Möller–Trumbore with raycast.py's determinant test;
 * shadow rays count hits with SHADOW_EPSILON < t < tmax − SHADOW_EPSILON, as
 * raycast.occluded. The hashed sample patterns are in sampling.glsl, which comes first. A
 * triangle packed with a negative |e1|·|e2| is a cut-out: kernels that define BVH_CUTOUTS (and
 * include textures.glsl, which defines bvh_cutout_counts) count its hits by its Alpha, as
 * textures.cutout_hits; others as opaque.
 * Kernels that define BVH_HIDDEN skip the triangles the ray's kind does not see (ray
 * visibility); render/gpu_bvh.py leaves both out of scenes that have none: llvmpipe runs a
 * branch's code in the triangle loop whether a lane takes it or not. */

#define BVH_WIDTH (1 << BVH_WIDTH_LOG2)
bool bvh_hidden(int slot, int ray);
#define BVH_FAR 1e30
#ifndef M_PI_F
#define M_PI_F 3.14159265358979323846
#endif
#ifdef BVH_CUTOUTS
bool bvh_cutout_counts(int triangle, vec2 uv, vec3 o, vec3 d);
#endif

vec4 bvh_texel_nodes(int k)
{
  return texelFetch(bvh_nodes, ivec2(k & (BVH_WIDTH - 1), k >> BVH_WIDTH_LOG2), 0);
}

vec4 bvh_texel_triangles(int k)
{
  return texelFetch(bvh_triangles, ivec2(k & (BVH_WIDTH - 1), k >> BVH_WIDTH_LOG2), 0);
}

/* The ray (o, d, |d| = dlen) against packed triangle `slot`: t, (u, v), or false; `cutout`:
 * the triangle is packed as a cut-out (a negative |e1|·|e2|). */
bool bvh_triangle(int slot, vec3 o, vec3 d, float dlen, out float t, out vec2 uv,
                  out bool cutout)
{
  vec4 a = bvh_texel_triangles(3 * slot);
  vec4 e1 = bvh_texel_triangles(3 * slot + 1);
  vec4 e2 = bvh_texel_triangles(3 * slot + 2);
  cutout = e2.w < 0.0;
  vec3 pv = cross(d, e2.xyz);
  float det = dot(e1.xyz, pv);
  t = BVH_FAR;
  uv = vec2(0.0);
  if (!(abs(det) > DET_EPSILON * abs(e2.w) * dlen)) {
    return false;
  }
  float inv = 1.0 / det;
  vec3 s = o - a.xyz;
  float u = dot(s, pv) * inv;
  if (u < 0.0 || u > 1.0) {
    return false;
  }
  vec3 q = cross(s, e1.xyz);
  float v = dot(d, q) * inv;
  if (v < 0.0 || u + v > 1.0) {
    return false;
  }
  t = dot(e2.xyz, q) * inv;
  uv = vec2(u, v);
  return true;
}

/* How far off a surface at p a ray starts: `least` (metres), or OFFSET_ULPS float32 steps of
 * p's largest coordinate where those are more (a scene far from the origin: at 3 km a step is
 * 0.24 mm, and a fixed 0.1 mm lift left the points inside their own surface, whose shadow
 * rays then hid it: docs/gi_pipeline.md "A scene far from the origin"). */
#define OFFSET_ULPS 16.0
float surface_offset(vec3 p, float least)
{
  vec3 a = abs(p);
  return max(least, OFFSET_ULPS * 1.1920929e-7 * max(a.x, max(a.y, a.z)));
}

/* Threaded traversal: the packed slot of the nearest hit with tmin < t < tmax (any hit when
 * any_hit), or -1; t_hit and uv of that hit. With BVH_CUTOUTS a cut-out's Alpha is not read
 * here (bvh_trace does, after the walk): `cut` says the slot is a cut-out, and an any-hit walk
 * returns an opaque hit at once, else the nearest cut-out on the segment. Hits are then
 * ordered by (t, slot), and a hit at t = tmin counts when its slot is above `skip`: a walk
 * again past a cut-out still meets a triangle in the cut-out's own plane (a pane in its
 * wall's opening, leaves on a card). */
int bvh_walk(vec3 o, vec3 d, float tmin, float tmax, bool any_hit, int skip, out float t_hit,
             out vec2 uv, out bool cut)
{
  vec3 safe = vec3(abs(d.x) > 1e-30 ? d.x : 1e-30, abs(d.y) > 1e-30 ? d.y : 1e-30,
                   abs(d.z) > 1e-30 ? d.z : 1e-30);
  vec3 inv = 1.0 / safe;
  float dlen = length(d);
  vec3 oinv = o * inv; /* slabs as lo·inv − o·inv: one multiply-add per axis */
  float best = tmax;
  int found = -1;
  uv = vec2(0.0);
  cut = false;
#ifdef BVH_CUTOUTS
  float cut_t = BVH_FAR;
  int cut_slot = -1;
  vec2 cut_uv = vec2(0.0);
#endif
  /* The nodes' layout (bvh.py pack_bvh: BVH_ORDERS layouts fill a multiple of BVH_ORDERS
   * rows, one layout one row more than a multiple). Of BVH_ORDERS, a closest hit walks the one
   * of its major direction, +x, −x, +y, −y, +z, −z (ordered_layouts: the nearer child first);
   * every shadow ray walks BVH_SHADOW_LAYOUT (−z, the upper child first): one order keeps the
   * eight lanes llvmpipe runs in lock step on the same nodes, and shadow rays toward the sun,
   * the sky and most lamps go up (docs/gi_pipeline.md "A layout of the BVH per ray direction":
   * by their own directions they went 20–30% slower than in any one order). */
  int rows = textureSize(bvh_nodes, 0).y;
  int base = 0;
  if (rows % BVH_ORDERS == 0) {
    vec3 ad = abs(d);
    int axis = ad.x >= ad.y ? (ad.x >= ad.z ? 0 : 2) : (ad.y >= ad.z ? 1 : 2);
    int order = any_hit ? BVH_SHADOW_LAYOUT : 2 * axis + (d[axis] < 0.0 ? 1 : 0);
    base = 2 * order * (rows / BVH_ORDERS) * (BVH_WIDTH / 2);
  }
  /* A step tests one triangle of the current leaf, then, once the leaf is done, one node
   * (Aila and Laine's if-if): llvmpipe runs eight lanes in lock step, and a lane in a leaf
   * held the others at their nodes for all of its triangles. The nodes and triangles come
   * in the same order as one leaf's loop at a time: the same hits. */
  int node = 0;
  int slot = 0, last = 0; /* the current leaf's triangles left */
  while (node >= 0 || slot < last) {
    if (slot < last) {
      float t;
      vec2 tuv;
      int current = slot++;
      bool is_cut;
#ifdef BVH_CUTOUTS
      bool hit = bvh_triangle(current, o, d, dlen, t, tuv, is_cut) &&
                 (t > tmin || (t == tmin && current > skip)) &&
                 (t < best || (t == best && current < found));
#else
      bool hit = bvh_triangle(current, o, d, dlen, t, tuv, is_cut) && t > tmin && t < best;
#endif
#ifdef BVH_HIDDEN
      hit = hit && !bvh_hidden(current, any_hit ? BVH_RAY_SHADOW : BVH_CLOSEST_RAY);
#endif
#ifdef BVH_CUTOUTS
      if (hit && any_hit && is_cut) {
        /* an opaque hit anywhere on the segment still ends the walk: the cut-outs wait */
        if (t < cut_t || (t == cut_t && current < cut_slot)) {
          cut_t = t;
          cut_slot = current;
          cut_uv = tuv;
        }
        hit = false;
      }
      cut = hit ? is_cut : cut;
#endif
      if (hit) {
        best = t;
        found = current;
        uv = tuv;
        if (any_hit) {
          t_hit = t;
          return found;
        }
      }
    }
    if (slot >= last && node >= 0) {
      vec4 lo = bvh_texel_nodes(base + 2 * node);
      vec4 hi = bvh_texel_nodes(base + 2 * node + 1);
      vec3 t0 = lo.xyz * inv - oinv;
      vec3 t1 = hi.xyz * inv - oinv;
      vec3 tn = min(t0, t1);
      vec3 tf = max(t0, t1);
      float enter = max(max(tn.x, tn.y), max(tn.z, tmin));
      float leave = min(min(tf.x, tf.y), min(tf.z, best));
      if (enter <= leave && hi.w < 0.0) {
        node += 1;
      }
      else {
        if (enter <= leave) {
          int code = floatBitsToInt(hi.w) - BVH_LEAF_BIAS; /* bvh.py LEAF_BIAS */
          slot = code >> 4;
          last = slot + (code & 15);
        }
        node = int(lo.w);
      }
    }
  }
#ifdef BVH_CUTOUTS
  if (any_hit && cut_slot >= 0) {
    cut = true;
    uv = cut_uv;
    t_hit = cut_t;
    return cut_slot;
  }
#endif
  t_hit = found >= 0 ? best : BVH_FAR;
  return found;
}

/* bvh_walk with the cut-outs' Alpha (textures.cutout_hits): a cut-out hit that does not count
 * walks again from past it, so the Alpha's texture and hashes run once a walk, outside the
 * triangle loop: inside it, llvmpipe ran their code at every triangle of every ray, and a scene
 * with a cut-out traced everything 2.5 × slower (docs/gi_pipeline.md "Cut-outs tested after the
 * walk"). Past BVH_CUTOUT_LAYERS cut-outs that do not count, the next hit counts whatever its
 * Alpha, as Cycles stops a path or a shadow ray past its Transparent bounces. The same hits as
 * a test inside the loop: the nearest that counts, or for any_hit whether one does. */
int bvh_trace(vec3 o, vec3 d, float tmin, float tmax, bool any_hit, out float t_hit, out vec2 uv)
{
  bool cut;
#ifdef BVH_CUTOUTS
  /* one call of bvh_walk, so that its code is built once */
  int found = -1;
  int skip = 0x7FFFFFFF; /* the first walk: t > tmin alone */
  for (int layer = 0; layer <= BVH_CUTOUT_LAYERS; layer++) {
    found = bvh_walk(o, d, tmin, tmax, any_hit, skip, t_hit, uv, cut);
    if (found < 0 || !cut || layer == BVH_CUTOUT_LAYERS ||
        bvh_cutout_counts(int(bvh_texel_triangles(3 * found + 1).w), uv, o, d)) {
      break;
    }
    tmin = t_hit;
    skip = found;
  }
  return found;
#else
  return bvh_walk(o, d, tmin, tmax, any_hit, 0x7FFFFFFF, t_hit, uv, cut);
#endif
}

/* Is anything in the way between SHADOW_EPSILON and tmax − SHADOW_EPSILON (d unit)? */
bool bvh_any_hit(vec3 o, vec3 d, float tmax)
{
  float t;
  vec2 uv;
  return bvh_trace(o, d, SHADOW_EPSILON, tmax - SHADOW_EPSILON, true, t, uv) >= 0;
}

/* Nearest hit with tmin < t < tmax: true and its distance, SceneTriangles index, packed slot
 * (for bvh_triangle_* lookups) and barycentrics (point = v0 + u·e1 + v·e2). */
bool bvh_closest_hit(vec3 o, vec3 d, float tmin, float tmax, out float t, out int triangle,
                     out int slot, out vec2 uv)
{
  slot = bvh_trace(o, d, tmin, tmax, false, t, uv);
  triangle = slot >= 0 ? int(bvh_texel_triangles(3 * slot + 1).w) : -1;
  return slot >= 0;
}

/* Ray visibility (bvh.py material_code): the RAY_* bits of the rays that do not see a triangle
 * are packed above its material index, code + 1 = material + 1 + 65536 · hidden. Closest hits
 * are rays of kind BVH_CLOSEST_RAY (a define per kernel: the gathers' diffuse or glossy bounce
 * rays), any hits shadow rays (BVH_RAY_SHADOW). */
int bvh_material_code(int slot)
{
  return int(bvh_texel_triangles(3 * slot).w) + 1;
}

bool bvh_hidden(int slot, int ray)
{
  return ((bvh_material_code(slot) >> 16) & ray) != 0;
}

int bvh_triangle_material(int slot)
{
  return (bvh_material_code(slot) & 0xFFFF) - 1;
}

/* Unit face normal of packed triangle `slot` (right-hand winding, as SceneTriangles.normals). */
vec3 bvh_triangle_face_normal(int slot)
{
  vec3 n = cross(bvh_texel_triangles(3 * slot + 1).xyz, bvh_texel_triangles(3 * slot + 2).xyz);
  float len = length(n);
  return len > 0.0 ? n / len : vec3(0.0);
}

/* The triangle under the surface point `q` seen along unit `view` (voxgi_addon/gi/
 * surface_lookup.py find_triangles: a ray from TERMINATOR_REACH in front of it to as far
 * behind): its packed slot, barycentrics and face normal on the side of the shading normal
 * `n`; false where none is found. */
bool surface_triangle(vec3 q, vec3 view, vec3 n, out int slot, out vec2 uv, out vec3 face)
{
  float th;
  int triangle;
  face = n;
  if (!bvh_closest_hit(q - TERMINATOR_REACH * view, view, 0.0, 2.0 * TERMINATOR_REACH, th,
                       triangle, slot, uv)) {
    return false;
  }
  face = cross(bvh_texel_triangles(3 * slot + 1).xyz, bvh_texel_triangles(3 * slot + 2).xyz);
  face /= max(length(face), 1e-30);
  face = dot(face, n) < 0.0 ? -face : face;
  return true;
}

/* The hashed sample patterns of voxgi_addon/gi/sampling.py, bit for bit: per-point hash
 * streams, jittered strata, rotated Hammersley sets, the concentric disc and a tangent frame.
 * Prepended to the BVH kernels (render/gpu_bvh.py) and to glossy_direct.glsl. */

#ifndef M_PI_F
#define M_PI_F 3.14159265358979323846
#endif

uint pcg_hash(uint v)
{
  uint state = v * 747796405u + 2891336453u;
  uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
  return (word >> 22u) ^ word;
}

float unit_float(uint h)
{
  return float(h >> 8u) * (1.0 / 16777216.0);
}

uint point_stream(uint id, uint stream, uint seed)
{
  return pcg_hash(pcg_hash(id + seed * 0x9E3779B9u) + stream);
}

/* Stratum k of a whole m × m set of a point's stream: (row, column) + jitter, / m. */
vec2 whole_stratum(uint state, int k, int m)
{
  vec2 jitter = vec2(unit_float(pcg_hash(state + uint(2 * k))),
                     unit_float(pcg_hash(state + uint(2 * k + 1))));
  return (vec2(float(k / m), float(k % m)) + jitter) / float(m);
}

/* Stratum k of m×m of a point's stream (sampling.hashed_square). A kernel that defines
 * STRATA_BLOCK = ivec3(M, row, column) (bvh_direct.glsl's sub-pixel passes) draws a block of a
 * larger set instead: stratum k of the loop's m × m is stratum (row + k / m, column + k % m) of
 * the M × M strata (direct_light.diffuse_direct's strata_block). */
vec2 hashed_stratum(uint state, int k, int m)
{
#ifdef STRATA_BLOCK
  ivec3 block = STRATA_BLOCK;
  k = (block.y + k / m) * block.x + block.z + k % m;
  m = block.x;
#endif
  return whole_stratum(state, k, m);
}

float radical_inverse(uint b)
{
  b = (b << 16u) | (b >> 16u);
  b = ((b & 0x55555555u) << 1u) | ((b & 0xAAAAAAAAu) >> 1u);
  b = ((b & 0x33333333u) << 2u) | ((b & 0xCCCCCCCCu) >> 2u);
  b = ((b & 0x0F0F0F0Fu) << 4u) | ((b & 0xF0F0F0F0u) >> 4u);
  b = ((b & 0x00FF00FFu) << 8u) | ((b & 0xFF00FF00u) >> 8u);
  return float(b >> 8u) * (1.0 / 16777216.0);
}

/* Point j of `count` of the rotated Hammersley set of a point's stream (sampling.hammersley). */
vec2 hammersley(uint state, int j, int count)
{
  vec2 rotation = vec2(unit_float(pcg_hash(state)), unit_float(pcg_hash(state + 1u)));
  vec2 u = vec2((float(j) + 0.5) / float(count), radical_inverse(uint(j))) + rotation;
  return u - floor(u);
}

/* Shirley–Chiu map of [0, 1)² to the unit disc (direct_light.concentric_disk). */
vec2 concentric_disk(vec2 s)
{
  float a = 2.0 * s.x - 1.0;
  float b = 2.0 * s.y - 1.0;
  if (a == 0.0 && b == 0.0) {
    return vec2(0.0);
  }
  bool first = abs(a) > abs(b);
  float r = first ? a : b;
  float phi = first ? (M_PI_F / 4.0) * b / a : M_PI_F / 2.0 - (M_PI_F / 4.0) * a / b;
  return r * vec2(cos(phi), sin(phi));
}

/* Tangents of unit w (sampling.perpendicular_basis). */
void perpendicular_basis(vec3 w, out vec3 t, out vec3 b)
{
  vec3 helper = abs(w.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
  t = normalize(cross(w, helper));
  b = cross(w, t);
}

/* GGX visible normal for the local view v (z > 0) and roughness alpha (Heitz 2018). */
vec3 vndf_half_vector(vec3 v, float alpha, vec2 u)
{
  vec3 vh = normalize(vec3(alpha * v.x, alpha * v.y, v.z));
  float lensq = vh.x * vh.x + vh.y * vh.y;
  vec3 t1 = lensq > 1e-7 ? vec3(-vh.y, vh.x, 0.0) / sqrt(lensq) : vec3(1.0, 0.0, 0.0);
  vec3 t2 = cross(vh, t1);
  float r = sqrt(u.x);
  float phi = 2.0 * 3.14159265358979323846 * u.y;
  float p1 = r * cos(phi);
  float p2 = r * sin(phi);
  float s = 0.5 * (1.0 + vh.z);
  p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2;
  float p3 = sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
  vec3 nh = p1 * t1 + p2 * t2 + p3 * vh;
  vec3 h = vec3(alpha * nh.x, alpha * nh.y, max(nh.z, 0.0));
  return h / max(length(h), 1e-30);
}

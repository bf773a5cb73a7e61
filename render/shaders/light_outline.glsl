/* An area lamp's unshadowed light over its outline (lights texels 8…, the convex polygon of
 * voxgi_addon/gi/direct_light.area_outline): Lambert's formula. Shared by the shadow rays'
 * kernels (bvh_lights.glsl) and the pixels' glossy light (glossy_direct.glsl); the kernel
 * defines light_texel (row `light` of the sampler `lights`, texel k). */

vec4 light_texel(int light, int k);

#define LUMA vec3(0.2126, 0.7152, 0.0722) /* Rec. 709 luminance */

/* Lambert's formula's term of the edge a → b (directions from the point) for its normal n. */
float edge_term(vec3 a, vec3 b, vec3 n)
{
  a = normalize(a);
  b = normalize(b);
  vec3 c = cross(a, b);
  float s = length(c);
  return atan(s, dot(a, b)) * dot(c, n) / max(s, 1e-30);
}

/* Lambert's formula (∫ cosθ/π dω) over the part of the convex outline above the horizon of
 * (p, n): the outline clipped by the tangent plane, the cut along the horizon from where it
 * leaves to where it comes back (direct_light._polygon_irradiance); aim = the mean of the
 * clipped outline's corners. */
float polygon_irradiance(int light, int count, vec3 p, vec3 n, out vec3 aim)
{
  float sum = 0.0;
  vec3 corners = vec3(0.0);
  float kept = 0.0;
  vec3 a = light_texel(light, 8).xyz - p;
  float ha = dot(a, n);
  vec3 exit_at = vec3(0.0), entry_at = vec3(0.0);
  bool left = false, entered = false;
  for (int k = 0; k < count; k++) {
    vec3 b = light_texel(light, 8 + (k + 1 < count ? k + 1 : 0)).xyz - p;
    float hb = dot(b, n);
    if (ha > 0.0 || hb > 0.0) {
      vec3 cut = a + (ha / (ha - hb)) * (b - a); /* used only where the edge crosses */
      if (ha > 0.0 && !(hb > 0.0)) {
        exit_at = cut;
        left = true;
      }
      if (!(ha > 0.0) && hb > 0.0) {
        entry_at = cut;
        entered = true;
      }
      sum += edge_term(ha > 0.0 ? a : cut, hb > 0.0 ? b : cut, n);
      corners += (ha > 0.0 ? a : vec3(0.0)) + ((ha > 0.0) != (hb > 0.0) ? cut : vec3(0.0));
      kept += (ha > 0.0 ? 1.0 : 0.0) + ((ha > 0.0) != (hb > 0.0) ? 1.0 : 0.0);
    }
    a = b;
    ha = hb;
  }
  if (left && entered) {
    sum += edge_term(exit_at, entry_at, n);
  }
  aim = p + corners / max(kept, 1.0);
  return abs(sum) / (2.0 * M_PI_F);
}


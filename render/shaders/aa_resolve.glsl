/* The sub-pixel samples of one pass resolved from the shaded pixel centres around them: the
 * port of voxgi_addon/preview/resolve.py resolve_samples (docs/gi_pipeline.md "Anti-aliasing
 * at the cost of a sample"). Per entry of the edge pixels' list (pixels = (x, y, id, 1),
 * aa_compact.glsl; gbuffer_* the pass's G-buffer there, position.w = 2 + id where it sees a
 * surface, 0 where not, -1 a holdout), the centres of its pixel's 3 × 3 that see the sample's
 * surface (centre_* the centres' G-buffer: same material, each on the other's tangent plane
 * within PLANE_TOLERANCE × their distance, and no texture on it: centre_base.w > 0.5, whose
 * colour the centre averages over its whole pixel; both seeing nothing, or both a holdout) and their
 * light (the light the centre pass's sums sum_* carry: emission and the four light passes,
 * summed over the channels). Where at least LEAST_CENTRES see it and their light spreads by at
 * most resolve.z of the largest, out_* = the bilinear blend of the sums of those of the 2 × 2
 * centres around the sample's place (the pass's offset resolve.xy, x right, y down, pixels)
 * that see it, or the nearest one of the 3 × 3 that does, and out_d.w = 1; elsewhere zeros
 * (the sample is shaded by the pass's kernels). */

vec3 sums_light(ivec2 q)
{
  return texelFetch(sum_a, q, 0).rgb + texelFetch(sum_d, q, 0).rgb +
         texelFetch(sum_e, q, 0).rgb + texelFetch(sum_f, q, 0).rgb +
         texelFetch(sum_g, q, 0).rgb;
}

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_a);
  if (t.x >= size.x || t.y >= size.y) {
    return;
  }
  vec4 a = vec4(0.0), b = vec4(0.0), c = vec4(0.0), d = vec4(0.0), e = vec4(0.0);
  vec4 f = vec4(0.0), g = vec4(0.0);
  vec4 pixel = texelFetch(pixels, t, 0);
  bool resolved = false;
  if (pixel.w > 0.5) {
    ivec2 full = textureSize(centre_position, 0);
    int id = int(pixel.z + 0.5);
    int row = id / full.x;
    int col = id - row * full.x;
    vec4 sp = texelFetch(gbuffer_position, t, 0);
    vec3 sn = texelFetch(gbuffer_normal, t, 0).xyz;
    int material = int(texelFetch(gbuffer_view, t, 0).w + 0.5);
    bool s_hit = sp.w > 0.5;
    bool s_holdout = sp.w < -0.5;
    float u = float(col) + resolve.x;
    float v = float(row) + resolve.y;
    int many = 0;
    float low = 1e30, high = -1e30, best = 1e30;
    ivec2 nearest = ivec2(-1);
    int sees = 0; /* bit (dr + 1) * 3 + dc + 1: that centre sees the sample's surface */
    for (int dr = -1; dr <= 1; dr++) {
      for (int dc = -1; dc <= 1; dc++) {
        int r = row + dr, cc = col + dc;
        if (r < 0 || r >= full.y || cc < 0 || cc >= full.x) {
          continue;
        }
        ivec2 q = ivec2(cc, full.y - 1 - r);
        vec4 cp = texelFetch(centre_position, q, 0);
        bool ok = (cp.w > 0.5) == s_hit && (cp.w < -0.5) == s_holdout;
        if (ok && s_hit) {
          vec3 step = cp.xyz - sp.xyz;
          vec3 cn = texelFetch(centre_normal, q, 0).xyz;
          float off_plane = max(abs(dot(sn, step)), abs(dot(cn, step)));
          ok = material == int(texelFetch(centre_view, q, 0).w + 0.5) &&
               off_plane <= PLANE_TOLERANCE * length(step) &&
               texelFetch(centre_base, q, 0).w < 0.5;
        }
        if (ok) {
          sees |= 1 << ((dr + 1) * 3 + dc + 1);
          vec3 l = sums_light(q);
          float light = l.r + l.g + l.b;
          many++;
          low = min(low, light);
          high = max(high, light);
          float d2 = (float(r) - v) * (float(r) - v) + (float(cc) - u) * (float(cc) - u);
          if (d2 < best) {
            best = d2;
            nearest = q;
          }
        }
      }
    }
    if (many >= LEAST_CENTRES && high - low <= resolve.z * max(high, 0.0)) {
      int row_step = int(floor(resolve.y));
      int col_step = int(floor(resolve.x));
      float fy = resolve.y - float(row_step);
      float fx = resolve.x - float(col_step);
      float weight = 0.0;
      for (int dr = 0; dr <= 1; dr++) {
        for (int dc = 0; dc <= 1; dc++) {
          if ((sees & (1 << ((row_step + dr + 1) * 3 + col_step + dc + 1))) == 0) {
            continue;
          }
          float w = (dr == 1 ? fy : 1.0 - fy) * (dc == 1 ? fx : 1.0 - fx) + 1e-6;
          ivec2 q = ivec2(col + col_step + dc, full.y - 1 - (row + row_step + dr));
          weight += w;
          a += w * texelFetch(sum_a, q, 0);
          b += w * texelFetch(sum_b, q, 0);
          c += w * texelFetch(sum_c, q, 0);
          d += w * texelFetch(sum_d, q, 0);
          e += w * texelFetch(sum_e, q, 0);
          f += w * texelFetch(sum_f, q, 0);
          g += w * texelFetch(sum_g, q, 0);
        }
      }
      if (weight > 0.0) {
        float inverse = 1.0 / weight;
        a *= inverse;
        b *= inverse;
        c *= inverse;
        d *= inverse;
        e *= inverse;
        f *= inverse;
        g *= inverse;
        resolved = true;
      }
      else { /* at least LEAST_CENTRES see it: there is a nearest */
        a = texelFetch(sum_a, nearest, 0);
        b = texelFetch(sum_b, nearest, 0);
        c = texelFetch(sum_c, nearest, 0);
        d = texelFetch(sum_d, nearest, 0);
        e = texelFetch(sum_e, nearest, 0);
        f = texelFetch(sum_f, nearest, 0);
        g = texelFetch(sum_g, nearest, 0);
        resolved = true;
      }
    }
  }
  imageStore(out_a, t, a);
  imageStore(out_b, t, b);
  imageStore(out_c, t, c);
  imageStore(out_d, t, vec4(d.rgb, resolved ? 1.0 : 0.0));
  imageStore(out_e, t, e);
  imageStore(out_f, t, f);
  imageStore(out_g, t, g);
}

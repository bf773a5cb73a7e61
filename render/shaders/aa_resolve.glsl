/* The sub-pixel samples of the passes one raster draws, resolved from the shaded pixel centres
 * around them: the port of voxgi_addon/preview/resolve.py resolve_samples (docs/gi_pipeline.md
 * "Anti-aliasing at the cost of a sample"), every pass of the raster in one invocation per
 * edge pixel, so the pixel's 3 × 3 centres are read once for all of them.
 *
 * Per entry of the edge pixels' list (pixels = (x, y, id, 1), GL coordinates, aa_compact.glsl)
 * and per pass p < resolve.x: the pass's sample is the texel (fine x + tx, fine y + fine − 1 −
 * ty) of the raster's G-buffer gbuffer_* (fine = resolve.z; passes row p = (offset x, offset
 * y, tx, ty): the pass's sub-pixel offset, x right, y down, pixels, and its sample in the
 * raster's fine × fine block; position.w > 0.5 where it sees a surface, −1 a holdout). The
 * centres of its pixel's 3 × 3 that see the sample's surface (centre_* the centres' G-buffer:
 * same material, each on the other's tangent plane within PLANE_TOLERANCE × their distance, and
 * no texture on it: centre_base.w > 0.5, whose colour the centre averages over its whole pixel;
 * both seeing nothing, or both a holdout) and their light (the light the centre pass's sums
 * sum_* carry: emission and the four light passes, summed over the channels). Where at least
 * LEAST_CENTRES see it and their light spreads by at most resolve.y of the largest, the pass's
 * out_* = the bilinear blend of the sums of those of the 2 × 2 centres around the sample's place
 * that see it, or the nearest one of the 3 × 3 that does, and out_d.w = 1; elsewhere zeros (the
 * sample is shaded by the pass's kernels). Pass p's outputs are rows p · resolve.w … of out_*
 * (resolve.w: the list's height).
 *
 * A sample on a textured surface (its raster texel gbuffer_base.w > 0.5) resolves its light
 * only: each centre's light passes over its colours (Diffuse Direct and Indirect over its
 * Diffuse Color, Glossy Direct and Indirect over its Glossy Color; a centre whose colours
 * have a channel below LEAST_COLOUR, unless that colour is black throughout, stands in for no
 * such sample), compared and blended as above, then coloured by the sample's own Principled
 * colours and emission at its texel (surface.glsl): a textured centre's colours are its whole
 * pixel's texture, not the sample's. */

vec3 sums_light(ivec2 q)
{
  return texelFetch(sum_a, q, 0).rgb + texelFetch(sum_d, q, 0).rgb +
         texelFetch(sum_e, q, 0).rgb + texelFetch(sum_f, q, 0).rgb +
         texelFetch(sum_g, q, 0).rgb;
}

/* light over colour, per channel; 0 where the colour is black throughout (a metal's diffuse) */
vec3 over(vec3 light, vec3 colour)
{
  return max(colour.r, max(colour.g, colour.b)) > 0.0 ? light / max(colour, LEAST_COLOUR) :
                                                       vec3(0.0);
}

/* whether a colour's light can be recovered: every channel at least LEAST_COLOUR, or black */
bool recoverable(vec3 colour)
{
  return min(colour.r, min(colour.g, colour.b)) >= LEAST_COLOUR ||
         max(colour.r, max(colour.g, colour.b)) <= 0.0;
}

/* w × the centre q's sums into a … g; by_light: its light passes over its colours, its
 * colours and emission left out (the sample's own colour them) */
void blend_at(ivec2 q, float w, bool by_light, inout vec4 a, inout vec4 b, inout vec4 c,
              inout vec4 d, inout vec4 e, inout vec4 f, inout vec4 g)
{
  vec4 sa = texelFetch(sum_a, q, 0), sb = texelFetch(sum_b, q, 0), sc = texelFetch(sum_c, q, 0);
  vec4 sd = texelFetch(sum_d, q, 0), se = texelFetch(sum_e, q, 0), sf = texelFetch(sum_f, q, 0);
  vec4 sg = texelFetch(sum_g, q, 0);
  if (by_light) {
    sd.rgb = over(sd.rgb, sb.rgb);
    sg.rgb = over(sg.rgb, sb.rgb);
    se.rgb = over(se.rgb, sc.rgb);
    sf.rgb = over(sf.rgb, sc.rgb);
    sa.rgb = sb.rgb = sc.rgb = vec3(0.0);
  }
  a += w * sa;
  b += w * sb;
  c += w * sc;
  d += w * sd;
  e += w * se;
  f += w * sf;
  g += w * sg;
}

void store(ivec2 t, vec4 a, vec4 b, vec4 c, vec4 d, vec4 e, vec4 f, vec4 g)
{
  imageStore(out_a, t, a);
  imageStore(out_b, t, b);
  imageStore(out_c, t, c);
  imageStore(out_d, t, d);
  imageStore(out_e, t, e);
  imageStore(out_f, t, f);
  imageStore(out_g, t, g);
}

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 list = textureSize(pixels, 0);
  if (t.x >= list.x || t.y >= list.y) {
    return;
  }
  int passes = int(resolve.x + 0.5);
  int fine = int(resolve.z + 0.5);
  int rows = int(resolve.w + 0.5);
  vec4 pixel = texelFetch(pixels, t, 0);
  if (pixel.w < 0.5) {
    for (int p = 0; p < passes; p++) {
      store(ivec2(t.x, t.y + p * rows), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0),
            vec4(0.0), vec4(0.0));
    }
    return;
  }
  ivec2 full = textureSize(centre_position, 0);
  int id = int(pixel.z + 0.5);
  int row = id / full.x;
  int col = id - row * full.x;
  /* the 3 × 3 centres, read once for every pass: index (dr + 1) * 3 + dc + 1 */
  vec4 c_position[9];
  vec3 c_normal[9];
  int c_material[9];
  bool c_there[9];
  bool c_plain[9];
  bool c_colours[9];  /* its light can be taken over its colours (a textured sample's) */
  float c_light[9];
  float c_own[9];     /* its light passes over its colours, summed (a textured sample's test) */
  for (int k = 0; k < 9; k++) {
    int r = row + k / 3 - 1, cc = col + k % 3 - 1;
    c_there[k] = r >= 0 && r < full.y && cc >= 0 && cc < full.x;
    ivec2 q = ivec2(clamp(cc, 0, full.x - 1), full.y - 1 - clamp(r, 0, full.y - 1));
    c_position[k] = texelFetch(centre_position, q, 0);
    c_normal[k] = texelFetch(centre_normal, q, 0).xyz;
    c_material[k] = int(texelFetch(centre_view, q, 0).w + 0.5);
    c_plain[k] = texelFetch(centre_base, q, 0).w < 0.5;
    vec3 l = sums_light(q);
    c_light[k] = l.r + l.g + l.b;
    vec3 diffuse = texelFetch(sum_b, q, 0).rgb, glossy = texelFetch(sum_c, q, 0).rgb;
    c_colours[k] = recoverable(diffuse) && recoverable(glossy);
    vec3 own = over(texelFetch(sum_d, q, 0).rgb + texelFetch(sum_g, q, 0).rgb, diffuse) +
               over(texelFetch(sum_e, q, 0).rgb + texelFetch(sum_f, q, 0).rgb, glossy);
    c_own[k] = own.r + own.g + own.b;
  }
  ivec2 block = ivec2(pixel.xy + 0.5) * fine;
  for (int p = 0; p < passes; p++) {
    vec4 pass = texelFetch(offsets, ivec2(p, 0), 0);
    ivec2 at = block + ivec2(int(pass.z + 0.5), fine - 1 - int(pass.w + 0.5));
    vec4 a = vec4(0.0), b = vec4(0.0), c = vec4(0.0), d = vec4(0.0), e = vec4(0.0);
    vec4 f = vec4(0.0), g = vec4(0.0);
    bool resolved = false;
    vec4 sp = texelFetch(gbuffer_position, at, 0);
    vec3 sn = texelFetch(gbuffer_normal, at, 0).xyz;
    vec4 ray = texelFetch(gbuffer_view, at, 0);
    int material = int(ray.w + 0.5);
    bool s_hit = sp.w > 0.5;
    bool s_holdout = sp.w < -0.5;
    vec4 texel = texelFetch(gbuffer_base, at, 0);
    bool by_light = s_hit && texel.w > 0.5;  /* a textured sample: its light alone */
    float u = float(col) + pass.x;
    float v = float(row) + pass.y;
    int many = 0;
    float low = 1e30, high = -1e30, best = 1e30;
    int nearest = -1;
    int sees = 0; /* bit k: centre k sees the sample's surface */
    for (int k = 0; k < 9; k++) {
      vec4 cp = c_position[k];
      bool ok = c_there[k] && (cp.w > 0.5) == s_hit && (cp.w < -0.5) == s_holdout;
      if (ok && s_hit) {
        vec3 step = cp.xyz - sp.xyz;
        float off_plane = max(abs(dot(sn, step)), abs(dot(c_normal[k], step)));
        ok = material == c_material[k] && off_plane <= PLANE_TOLERANCE * length(step) &&
             (by_light ? c_colours[k] : c_plain[k]);
      }
      if (ok) {
        sees |= 1 << k;
        many++;
        float light = by_light ? c_own[k] : c_light[k];
        low = min(low, light);
        high = max(high, light);
        float dr = float(row + k / 3 - 1) - v, dc = float(col + k % 3 - 1) - u;
        float d2 = dr * dr + dc * dc;
        if (d2 < best) {
          best = d2;
          nearest = k;
        }
      }
    }
    if (many >= LEAST_CENTRES && high - low <= resolve.y * max(high, 0.0)) {
      int row_step = int(floor(pass.y));
      int col_step = int(floor(pass.x));
      float fy = pass.y - float(row_step);
      float fx = pass.x - float(col_step);
      float weight = 0.0;
      for (int dr = 0; dr <= 1; dr++) {
        for (int dc = 0; dc <= 1; dc++) {
          if ((sees & (1 << ((row_step + dr + 1) * 3 + col_step + dc + 1))) == 0) {
            continue;
          }
          float w = (dr == 1 ? fy : 1.0 - fy) * (dc == 1 ? fx : 1.0 - fx) + 1e-6;
          ivec2 q = ivec2(col + col_step + dc, full.y - 1 - (row + row_step + dr));
          weight += w;
          blend_at(q, w, by_light, a, b, c, d, e, f, g);
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
      }
      else { /* at least LEAST_CENTRES see it: there is a nearest */
        blend_at(ivec2(col + nearest % 3 - 1, full.y - 1 - (row + nearest / 3 - 1)), 1.0,
                 by_light, a, b, c, d, e, f, g);
      }
      if (by_light) {  /* the light coloured by the sample's own colours and emission */
        vec3 diffuse_colour, glossy_colour, emission;
        surface_colours(texel, sn, ray, diffuse_colour, glossy_colour, emission);
        a.rgb = emission;
        b.rgb = diffuse_colour;
        c.rgb = glossy_colour;
        d.rgb *= diffuse_colour;
        g.rgb *= diffuse_colour;
        e.rgb *= glossy_colour;
        f.rgb *= glossy_colour;
      }
      resolved = true;
    }
    store(ivec2(t.x, t.y + p * rows), a, b, c, vec4(d.rgb, resolved ? 1.0 : 0.0), e, f, g);
  }
}

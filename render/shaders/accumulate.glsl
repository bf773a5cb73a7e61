/* One viewport sample of one tile added into the image's sums on the GPU
 * (voxgi_addon/preview/progressive.Accumulation.add, the readable reference).
 *
 * `acc` and `tails` hold LAYERS layers of the W × H image stacked vertically (layer l, pixel
 * (x, y) with y from the top at texel (x, l·H + H − 1 − y)):
 *   0 (sums rgb, count)  1 (weights rgb, gather weights)  2 (gathered light rgb, film weights)
 *   3 (film: world rgb, coverage)  4 (film: holdout, 0, 0, 0)
 * `tails` the same sums spread into the 8 neighbours by the pixel filter at the sample's
 * offset (no counts). The sample's terms (pass_sample.glsl, or preview.progressive.
 * sample_terms uploaded) are tile-sized textures, rows bottom to top:
 *   sample_value (value, coverage), sample_weight (weight, holdout), sample_light (light, 0);
 * world_image: the world along the tile's camera rays.
 *
 * rect: the tile (x0, y0 from the top, w, h) in image pixels; window: the pixels this dispatch
 * covers (x0, y0, w, h: the tile's inside the image grown by one for the tails);
 * mode: (kind 0 plain / 1 light pass / 2 Combined, weight, gather weight, film);
 * info: (W, H, has world, a); tail_a, tail_b, tail_c: the 3 × 3 tail weights row-major
 * (w[ey + 1][ex + 1], ey down), the centre's unused.
 * a > 0: centre_position, centre_normal, centre_view, centre_base hold the tile's G-buffer
 * (same_surface.glsl; gbuffer_frag.glsl's out_base), and a sample goes into a neighbour of the
 * tile across a step of one surface's texture (texture_step; the reference: preview.progressive
 * .texture_steps) by the filter's mean weights (a at the sides, a² at the corners:
 * passes.neighbour_weights) instead of its offset's. */

bool in_tile(ivec2 s)
{
  ivec2 image = ivec2(info.xy);
  ivec4 r = ivec4(rect);
  return s.x >= max(r.x, 0) && s.x < min(r.x + r.z, image.x) && s.y >= max(r.y, 0) &&
         s.y < min(r.y + r.w, image.y);
}

void sample_at(ivec2 s, out vec4 c[LAYERS])
{
  ivec4 r = ivec4(rect);
  ivec2 t = ivec2(s.x - r.x, r.w - 1 - (s.y - r.y));
  vec4 value = texelFetch(sample_value, t, 0);
  vec4 weight = texelFetch(sample_weight, t, 0);
  vec3 light = texelFetch(sample_light, t, 0).rgb;
  bool combined = mode.x > 1.5;
  bool film = mode.w > 0.5;
  c[0] = vec4(mode.y * value.rgb, 0.0);
  c[1] = vec4(mode.y * weight.rgb, combined ? mode.z : 0.0);
  c[2] = vec4(combined ? mode.z * light : vec3(0.0), film ? 1.0 : 0.0);
  vec3 world = (film && info.z > 0.5) ? texelFetch(world_image, t, 0).rgb : vec3(0.0);
  c[3] = film ? vec4(world, value.a) : vec4(0.0);
  c[4] = film ? vec4(weight.a, 0.0, 0.0, 0.0) : vec4(0.0);
}

float tail_weight(int k)
{
  return k < 4 ? tail_a[k] : (k < 8 ? tail_b[k - 4] : tail_c[k - 8]);
}

ivec2 tile_texel(ivec2 s)
{
  ivec4 r = ivec4(rect);
  return ivec2(s.x - r.x, r.w - 1 - (s.y - r.y));
}

/* whether the tile's pixels s and p (both in the tile) see one surface whose texture differs
 * between them */
bool texture_step(ivec2 s, ivec2 p)
{
  ivec2 t = tile_texel(s), u = tile_texel(p);
  vec4 position = texelFetch(centre_position, t, 0);
  vec4 base = texelFetch(centre_base, t, 0);
  vec4 other = texelFetch(centre_base, u, 0);
  return position.w >= 0.5 && base.w > 0.5 && other.w > 0.5 &&
         distance(base.rgb, other.rgb) > TEXTURE_STEP &&
         same_surface(position, texelFetch(centre_normal, t, 0).xyz,
                      texelFetch(centre_view, t, 0).w, u);
}

void main()
{
  ivec2 p;
  if (!window_pixel(p)) {
    return;
  }
  vec4 c[LAYERS];
  bool own = in_tile(p);
  if (own) {
    sample_at(p, c);
    for (int l = 0; l < LAYERS; l++) {
      ivec2 at = layer_texel(p, l);
      imageStore(acc, at, imageLoad(acc, at) + c[l] + (l == 0 ? vec4(0.0, 0.0, 0.0, 1.0) :
                                                                  vec4(0.0)));
    }
  }
  vec4 spread[LAYERS];
  for (int l = 0; l < LAYERS; l++) {
    spread[l] = vec4(0.0);
  }
  bool any = false;
  for (int ey = -1; ey <= 1; ey++) {
    for (int ex = -1; ex <= 1; ex++) {
      int k = (ey + 1) * 3 + ex + 1;
      float weight = tail_weight(k);
      ivec2 s = p + ivec2(ex, ey);
      if (k == 4 || !in_tile(s)) {
        continue;
      }
      if (info.w > 0.0 && own && texture_step(s, p)) {
        weight = (ex != 0 && ey != 0) ? info.w * info.w : info.w;
      }
      if (weight == 0.0) {
        continue;
      }
      sample_at(s, c);
      for (int l = 0; l < LAYERS; l++) {
        spread[l] += weight * c[l];
      }
      any = true;
    }
  }
  if (any) {
    for (int l = 0; l < LAYERS; l++) {
      ivec2 at = layer_texel(p, l);
      imageStore(tails, at, imageLoad(tails, at) + spread[l]);
    }
  }
}

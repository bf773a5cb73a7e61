/* The viewport's current image from its GPU sums (accumulate.glsl's layers; the readable
 * reference: voxgi_addon/preview/progressive.Accumulation.estimate_rgba / film_rgba): per
 * pixel the mean of the sums with their tails (the samples so far, the pixel's own and its
 * neighbours' by Cycles' pixel filter: the image filtered as F12's at every sample) — sums /
 * weights per channel + gathered / gather weights — on the film (preview/film.film_combined:
 * the world behind the share no surface or holdout covers, alpha 1 − holdout; Film ›
 * Transparent: alpha = coverage) or with alpha 1; where no sample of its own landed yet, the
 * backdrop (any size, nearest pixel; preview.progressive.scale_nearest). Writes out_image
 * (W × H, rows bottom to top) over window (x0, y0 from the top, w, h) only.
 * info: (W, H, backdrop w, backdrop h); mode: (film, transparent, 0, has backdrop: 1, or 2
 * before any sample, the sums then 1 × 1 blanks that are not read). */

float safe_ratio(float a, float b)
{
  return b > 0.0 ? a / b : 0.0;
}

/* The backdrop's nearest pixel to p (preview.progressive.scale_nearest). */
vec4 backdrop_at(ivec2 p, ivec2 image)
{
  ivec2 back = ivec2(info.zw);
  int row = min(int((float(p.y) + 0.5) * float(back.y) / float(image.y)), back.y - 1);
  int col = min(int((float(p.x) + 0.5) * float(back.x) / float(image.x)), back.x - 1);
  return texelFetch(backdrop, ivec2(col, back.y - 1 - row), 0);
}

void main()
{
  ivec2 p;
  if (!window_pixel(p)) {
    return;
  }
  ivec2 image = ivec2(info.xy);
  ivec2 out_texel = ivec2(p.x, image.y - 1 - p.y);
  if (mode.w > 1.5) {
    imageStore(out_image, out_texel, backdrop_at(p, image));
    return;
  }
  vec4 L[LAYERS];
  for (int l = 0; l < LAYERS; l++) {
    L[l] = texelFetch(acc, layer_texel(p, l), 0) + texelFetch(tails, layer_texel(p, l), 0);
  }
  float count = texelFetch(acc, layer_texel(p, 0), 0).a;
  if (count < 0.5 && mode.w > 0.5) {
    imageStore(out_image, out_texel, backdrop_at(p, image));
    return;
  }
  vec3 mean = vec3(safe_ratio(L[0].r, L[1].r), safe_ratio(L[0].g, L[1].g),
                   safe_ratio(L[0].b, L[1].b));
  if (L[1].a > 0.0) {
    mean += L[2].rgb / L[1].a;
  }
  vec4 rgba = vec4(mean, 1.0);
  if (mode.x > 0.5) {
    vec4 shares = L[2].a > 0.0 ? L[3] / L[2].a : vec4(0.0);
    float holdout = L[2].a > 0.0 ? L[4].x / L[2].a : 0.0;
    float alpha = clamp(shares.a, 0.0, 1.0);
    float held = clamp(holdout, 0.0, 1.0 - alpha);
    rgba = mode.y > 0.5 ? vec4(mean, alpha) :
                          vec4(mean + (1.0 - alpha - held) * shares.rgb, 1.0 - held);
  }
  imageStore(out_image, out_texel, rgba);
}

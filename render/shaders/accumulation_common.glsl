/* Shared by accumulate.glsl and estimate.glsl: the viewport's sums are LAYERS layers of the
 * W × H image (info.xy) stacked vertically in one texture, layer l's pixel (x, y) — y from the
 * top — at texel (x, l·H + H − 1 − y); a dispatch covers `window` (x0, y0 from the top, w, h)
 * of the image. */

#define LAYERS 5

ivec2 layer_texel(ivec2 p, int layer)
{
  int height = int(info.y);
  return ivec2(p.x, layer * height + height - 1 - p.y);
}

/* This invocation's pixel of the window (y from the top); false past the window. */
bool window_pixel(out ivec2 p)
{
  ivec2 g = ivec2(gl_GlobalInvocationID.xy);
  ivec4 w = ivec4(window);
  p = ivec2(w.x + g.x, w.y + g.y);
  return g.x < w.z && g.y < w.w;
}

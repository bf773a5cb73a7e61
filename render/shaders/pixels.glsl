/* The full-resolution G-buffer pixel traced for low-resolution cell (row j from the top,
 * column i) at a reduced GI resolution (preview/upsample.sample_pixels; GL rows count from the
 * bottom). */
ivec2 traced_pixel(int j, int i, int stride, ivec2 full)
{
  int top_row = min(j * stride + stride / 2, full.y - 1);
  return ivec2(min(i * stride + stride / 2, full.x - 1), full.y - 1 - top_row);
}


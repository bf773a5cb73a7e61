/* The sub-pixel passes' samples of the edge pixels summed into the pixels their filter reaches
 * (render/gpu_tails.py; the numpy statement: voxgi_addon/preview/passes.py stacked_tails, plus
 * each edge pixel's own weighted sum). One invocation per entry of the reached pixels' list
 * reached = (x, y, id, 1) (GL coordinates, id its index in the image, row 0 on top; zeros pad
 * the list), run once per raster: its passes' samples are added to the sums.
 *
 * index: the image (W × H, GL rows) holding 1 + the list index of each edge pixel (0 elsewhere).
 * sample_a … sample_g: the raster's samples, row k · tails.y + r of them the pass k's sample of
 * the edge pixel at list texel (x, r) (aa_resolve.glsl's rows; a list tails.z wide).
 * weights: texel (k, e) = the weight with which the pass k's sample of pixel p + e counts in p,
 * e = (e / 3 − 1 rows down, e % 3 − 1 columns right); e = 4 its own pixel.
 * tails = (passes of this raster, the list's rows per pass, the list's width, 0).
 * sums_*: the sums over the passes so far, read and written at the entry's texel. */

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(sums_a);
  if (t.x >= size.x || t.y >= size.y) {
    return;
  }
  vec4 entry = texelFetch(reached, t, 0);
  if (entry.w < 0.5) {
    return;
  }
  ivec2 full = textureSize(index, 0);
  int id = int(entry.z + 0.5);
  int row = id / full.x;
  int col = id - row * full.x;
  int passes = int(tails.x + 0.5);
  int rows = int(tails.y + 0.5);
  int side = int(tails.z + 0.5);
  vec4 a = imageLoad(sums_a, t), b = imageLoad(sums_b, t), c = imageLoad(sums_c, t);
  vec4 d = imageLoad(sums_d, t), e = imageLoad(sums_e, t), f = imageLoad(sums_f, t);
  vec4 g = imageLoad(sums_g, t);
  for (int k = 0; k < 9; k++) {
    int r = row + k / 3 - 1, cc = col + k % 3 - 1;
    if (r < 0 || r >= full.y || cc < 0 || cc >= full.x) {
      continue;
    }
    int n = int(texelFetch(index, ivec2(cc, full.y - 1 - r), 0).x + 0.5) - 1;
    if (n < 0) {
      continue;
    }
    ivec2 at = ivec2(n % side, n / side);
    for (int p = 0; p < passes; p++) {
      float w = texelFetch(weights, ivec2(p, k), 0).x;
      ivec2 s = at + ivec2(0, p * rows);
      a += w * texelFetch(sample_a, s, 0);
      b += w * texelFetch(sample_b, s, 0);
      c += w * texelFetch(sample_c, s, 0);
      d += w * texelFetch(sample_d, s, 0);
      e += w * texelFetch(sample_e, s, 0);
      f += w * texelFetch(sample_f, s, 0);
      g += w * texelFetch(sample_g, s, 0);
    }
  }
  imageStore(sums_a, t, a);
  imageStore(sums_b, t, b);
  imageStore(sums_c, t, c);
  imageStore(sums_d, t, d);
  imageStore(sums_e, t, e);
  imageStore(sums_f, t, f);
  imageStore(sums_g, t, g);
}

/* One sample's raw gather of one tile added to the samples' sums of the image's low-resolution
 * gather grid (render/gpu_gather_sums.py; the numpy statement: voxgi_addon/preview/progressive.py
 * GatherSums.add). One invocation per cell of the tile's low grid (the size of out_mean).
 *
 * gather_values, gather_variance: the tile's raw gather (rgb, a) and its kernel variances, GL
 * rows (row 0 at the bottom); NaN (a cell of no surface) counts as 0.
 * sums: the kind's sums over the image's low grid (Wl × Hl), three layers stacked in rows:
 * [0, Hl) Σ values, [Hl, 2 Hl) Σ variances, [2 Hl, 3 Hl) (Σ luminance², count, 0, 0); in each
 * layer GL rows too (image low row r from the top at layer row Hl − 1 − r).
 * cells = (x0 / stride, y0 / stride, rays per point, 1: read only): the tile's first low cell
 * in the image's low grid (its column, its row from the top; either may be negative). Read only
 * (a sample after the gathering ones, voxgi_addon/preview/progressive.py sample_settings):
 * nothing is added and the gather textures are not read, every cell of the tile takes the
 * image's nearest cell's mean and pooled variance (rays: those of the samples summed).
 * out_mean, out_pooled: the mean of every sample so far and the pooled variance (Σ var / n²;
 * with one ray per point the luminance's is the samples' spread, (Σ l² / n − l̄²) / (n − 1),
 * once n > 1); cells of the tile past the image keep the tile's own gather. */

const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);

vec4 finite(vec4 v)
{
  return vec4(isnan(v.x) ? 0.0 : v.x, isnan(v.y) ? 0.0 : v.y, isnan(v.z) ? 0.0 : v.z,
              isnan(v.w) ? 0.0 : v.w);
}

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_mean);
  if (t.x >= size.x || t.y >= size.y) {
    return;
  }
  ivec2 grid = imageSize(sums);
  grid.y /= 3;
  int col = int(floor(cells.x + 0.5)) + t.x;
  int row = int(floor(cells.y + 0.5)) + (size.y - 1 - t.y); /* from the image's top */
  bool read_only = cells.w > 0.5;
  if (read_only) {
    col = clamp(col, 0, grid.x - 1);
    row = clamp(row, 0, grid.y - 1);
  }
  vec4 value = read_only ? vec4(0.0) : finite(texelFetch(gather_values, t, 0));
  vec4 variance = read_only ? vec4(0.0) : finite(texelFetch(gather_variance, t, 0));
  if (col < 0 || row < 0 || col >= grid.x || row >= grid.y) {
    imageStore(out_mean, t, value); /* past the image: the tile's own gather */
    imageStore(out_pooled, t, variance);
    return;
  }
  ivec2 at = ivec2(col, grid.y - 1 - row);
  ivec2 layer = ivec2(0, grid.y);
  float lum = dot(value.rgb, LUMINANCE);
  vec4 sum_values = imageLoad(sums, at) + value;
  vec4 sum_variance = imageLoad(sums, at + layer) + variance;
  vec4 rest = imageLoad(sums, at + 2 * layer) + vec4(lum * lum, read_only ? 0.0 : 1.0, 0.0, 0.0);
  if (!read_only) {
    imageStore(sums, at, sum_values);
    imageStore(sums, at + layer, sum_variance);
    imageStore(sums, at + 2 * layer, rest);
  }
  float n = max(rest.y, 1.0);
  vec4 mean = sum_values / n;
  vec4 pooled = sum_variance / (n * n);
  if (cells.z <= 1.0 && n > 1.0) { /* one ray: its kernel variance is 0, take the spread */
    float l = dot(mean.rgb, LUMINANCE);
    pooled.x = max(rest.x / n - l * l, 0.0) / max(n - 1.0, 1.0);
  }
  imageStore(out_mean, t, mean);
  imageStore(out_pooled, t, pooled);
}

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
 * cells.w = 2, the lattice (gpu_gather.gather_steps' lattice): the gather textures hold only
 * the tile's cells of odd row and column from its top-left (clamped to its last row and
 * column), the lattice's shape; the tile's other cells add nothing.
 * A cell no sample has reached yet is a hole: out_pooled.z = 1 (denoise.glsl fills it).
 * out_mean, out_pooled: the mean of every sample so far and the pooled variance (Σ var / n²;
 * with one ray per point the luminance's is the samples' spread, (Σ l² / n − l̄²) / (n − 1),
 * once n > 1), its .z 0: the view's filter bounds no tap by the points' reach, which F12's does
 * (bvh_gather.glsl, denoise.glsl; docs/gi_pipeline.md "The filter's taps within the gather
 * points' reach": the converged view then lies nearer F12's image); cells of the tile past the
 * image keep the tile's own gather. */

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
  bool read_only = cells.w > 0.5 && cells.w < 1.5;
  bool lattice = cells.w > 1.5;
  if (read_only) {
    col = clamp(col, 0, grid.x - 1);
    row = clamp(row, 0, grid.y - 1);
  }
  /* the tile's cell in the gather textures (the lattice: its lattice cell, if it is one) */
  ivec2 at_gather = t;
  bool adds = !read_only;
  if (lattice) {
    int top = size.y - 1 - t.y; /* the cell's row from the tile's top */
    adds = min(2 * (top / 2) + 1, size.y - 1) == top && min(2 * (t.x / 2) + 1, size.x - 1) == t.x;
    at_gather = ivec2(t.x / 2, (size.y + 1) / 2 - 1 - top / 2);
  }
  vec4 value = adds ? finite(texelFetch(gather_values, at_gather, 0)) : vec4(0.0);
  vec4 variance = adds ? finite(texelFetch(gather_variance, at_gather, 0)) : vec4(0.0);
  if (col < 0 || row < 0 || col >= grid.x || row >= grid.y) {
    /* past the image: the tile's own gather (a hole off the lattice) */
    imageStore(out_mean, t, value);
    imageStore(out_pooled, t, lattice && !adds ? vec4(0.0, 0.0, 1.0, 0.0) : variance);
    return;
  }
  ivec2 at = ivec2(col, grid.y - 1 - row);
  ivec2 layer = ivec2(0, grid.y);
  float lum = dot(value.rgb, LUMINANCE);
  vec4 sum_values = imageLoad(sums, at) + value;
  vec4 sum_variance = imageLoad(sums, at + layer) + variance;
  vec4 rest = imageLoad(sums, at + 2 * layer) + vec4(lum * lum, adds ? 1.0 : 0.0, 0.0, 0.0);
  if (adds) {
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
  pooled.z = rest.y > 0.5 ? 0.0 : 1.0; /* no reach; a hole: 1 */
  imageStore(out_mean, t, mean);
  imageStore(out_pooled, t, pooled);
}

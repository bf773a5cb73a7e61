/* The gather point of low-resolution cell `cell` of the gathers (bvh_gather.glsl,
 * bvh_glossy.glsl; grid = (stride, full width, full height, w)): false for a cell outside the
 * grid, or whose G-buffer pixel sees no surface (its outputs are then written 0). Otherwise
 * the surface point stepped back along the camera ray by VIEW_BACKOFF (preview/gather.py), its
 * normal, the G-buffer's view texel (camera ray direction, material) and the sample id (the
 * pixel index, row 0 on top; a compacted list's point: its pixel's, sparse_gather).
 * grid.w holds flags: with 2 the cells are the lattice of the stride's grid (odd row, odd
 * column, counted from the top-left, clamped to its last row and column: gpu_gather
 * .gather_steps' lattice), cell (i, j) the stride's cell (2 i + 1, 2 j + 1); 1 and 4 are the
 * kernels' own (bvh_glossy.glsl's world mode, bvh_gather.glsl's sun apart). */
bool gather_point(ivec2 cell, out vec3 position, out vec3 n, out vec4 ray, out uint id)
{
  position = n = vec3(0.0);
  ray = vec4(0.0);
  id = 0u;
  ivec2 size = imageSize(out_image);
  if (cell.x >= size.x || cell.y >= size.y) {
    return false;
  }
  ivec2 full = ivec2(grid.yz);
  int stride = int(grid.x);
  int top = size.y - 1 - cell.y;
  int column = cell.x;
  if ((int(grid.w + 0.5) & 2) != 0) { /* the lattice of the stride's grid */
    top = min(2 * top + 1, (full.y + stride - 1) / stride - 1);
    column = min(2 * column + 1, (full.x + stride - 1) / stride - 1);
  }
  ivec2 px = traced_pixel(top, column, stride, full);
  vec4 p = texelFetch(gbuffer_position, px, 0);
  if (p.w < 0.5) {
    imageStore(out_image, cell, vec4(0.0));
    imageStore(out_variance, cell, vec4(0.0));
    return false;
  }
  n = texelFetch(gbuffer_normal, px, 0).xyz;
  ray = texelFetch(gbuffer_view, px, 0);
  position = p.xyz - VIEW_BACKOFF * ray.xyz;
  /* a listed point (aa_compact.glsl: w = 2 + its pixel's id) draws its pixel's samples */
  id = p.w > 1.5 ? uint(p.w + 0.5) - 2u : uint((full.y - 1 - px.y) * full.x + px.x);
  return true;
}

/* Diffuse Direct per G-buffer pixel with shadow rays through the BVH (bvh_lights.glsl): what
 * preview.direct_light computes with shadows "RAYS" — diffuse_direct at the point lifted by
 * SURFACE_EPSILON along its normal, sample id = pixel index (row 0 on top).
 * Push constants: sampling = (seed, strata side m of this dispatch, 0, 0); strata = (M, row,
 * column, 0): the dispatch draws the m × m block at (row, column) of each light's M × M strata
 * (sampling.glsl STRATA_BLOCK; the whole set when m = M), so the anti-aliased preview's
 * sub-pixel passes share one stratified set of shadow rays. out = (rgb, 1). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  uint id = position.w > 1.5 ? uint(position.w) - 2u  /* a listed pixel: aa_compact.glsl */
                             : uint((size.y - 1 - px.y) * size.x + px.x);
  vec3 value = diffuse_direct(position.xyz + n * SURFACE_EPSILON, n, id, uint(sampling.x),
                              int(sampling.y));
  imageStore(out_image, px, vec4(value, 1.0));
}

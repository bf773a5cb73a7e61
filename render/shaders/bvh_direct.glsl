/* Diffuse Direct per G-buffer pixel with shadow rays through the BVH (bvh_lights.glsl): what
 * preview.direct_light computes with shadows "RAYS" — diffuse_direct at the point lifted by
 * SURFACE_EPSILON along its normal, sample id = pixel index (row 0 on top).
 * Push constants: sampling = (seed, strata side m of this dispatch, mode, 0); strata = (M, row,
 * column, 0): the dispatch draws the m × m block at (row, column) of each light's M × M strata
 * (sampling.glsl STRATA_BLOCK; the whole set when m = M), so the anti-aliased preview's
 * sub-pixel passes share one stratified set of shadow rays. out = (rgb, 1).
 * gbuffer_view = (ray direction, material). sampling.z, the mode:
 * 0: Diffuse Direct, the emitters' exact unshadowed sum evaluated at every texel
 * (O(emissive triangles), bvh_lights.glsl emitters_unshadowed);
 * 1, the same in a pass of the anti-aliased preview: centre_position, centre_normal,
 * centre_view hold the pixel centres' G-buffer at the same texels and centre_unshadowed mode
 * 2's output there; a texel whose pass sees the surface its centre sees (same_surface.glsl)
 * takes the centre's sum, the others evaluate it at their own point (the shadow rays are the
 * pass's own);
 * 2: out = (the emitters' exact unshadowed sum alone, emitters_unshadowed, 1), no rays. */

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
  vec3 p = position.xyz + n * SURFACE_EPSILON;
  int mode = int(sampling.z + 0.5);
  if (mode == 2) {
    imageStore(out_image, px, vec4(emitters_unshadowed(p, n, true), 1.0));
    return;
  }
  vec4 known = vec4(0.0); /* w = 0: evaluated here */
  if (mode == 1 && same_surface(position, n, texelFetch(gbuffer_view, px, 0).w, px)) {
    known = vec4(texelFetch(centre_unshadowed, px, 0).rgb, 1.0);
  }
  uint id = position.w > 1.5 ? uint(position.w) - 2u  /* a listed pixel: aa_compact.glsl */
                             : uint((size.y - 1 - px.y) * size.x + px.x);
  vec3 value = diffuse_direct(p, n, id, uint(sampling.x), int(sampling.y), known);
  imageStore(out_image, px, vec4(value, 1.0));
}

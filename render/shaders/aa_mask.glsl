/* The pixels one pass of the anti-aliased preview shades (preview/passes.adaptive_passes): a
 * copy of the pass's G-buffer positions whose coverage (w) is 0 where `pixels` (.x) is 0, so
 * that every kernel of the pass (bvh_direct, glossy_direct, aa_surface, aa_light) returns early
 * there as on the background, and adds nothing to the sums. */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_position);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  float keep = texelFetch(pixels, px, 0).x;
  imageStore(out_position, px, vec4(position.xyz, keep > 0.5 ? position.w : 0.0));
}

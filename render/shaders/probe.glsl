/* Test kernel: out = the volume's sample at gbuffer_position.xyz, level gbuffer_position.w,
 * for a cone along gbuffer_normal.xyz (anisotropic when gbuffer_normal.w > 0.5); the blended
 * alpha replaces .w when gbuffer_view.x > 0.5. */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  load_params();
  if (px.x >= imageSize(out_image).x || px.y >= imageSize(out_image).y) {
    return;
  }
  vec4 q = texelFetch(gbuffer_position, px, 0);
  vec4 d = texelFetch(gbuffer_normal, px, 0);
  float blended;
  vec4 v = sample_volume(q.w, q.xyz, d.xyz, d.w > 0.5, blended);
  if (texelFetch(gbuffer_view, px, 0).x > 0.5) {
    v.w = blended;
  }
  imageStore(out_image, px, v);
}

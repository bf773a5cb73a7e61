/* One light's share of one sub-pixel pass of the anti-aliased preview (the lights' terms of
 * voxgi_addon/preview/passes.accumulate_pass): sum_f (glossy light) += shine_image (that
 * light's Glossy Color × Glossy Direct, glossy_direct.glsl), sum_g (Diffuse Color × Diffuse
 * Direct) += colour (this pass's Diffuse Color, aa_surface.glsl) × direct_image (that light's
 * Diffuse Direct, bvh_direct.glsl). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_f);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec3 diffuse_colour = texelFetch(colour, px, 0).rgb;
  imageStore(out_f, px, texelFetch(sum_f, px, 0) + vec4(texelFetch(shine_image, px, 0).rgb, 0.0));
  imageStore(out_g, px, texelFetch(sum_g, px, 0) +
                            vec4(diffuse_colour * texelFetch(direct_image, px, 0).rgb, 0.0));
}

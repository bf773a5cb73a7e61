/* One sub-pixel pass of the anti-aliased preview, its light-independent part: the port of
 * voxgi_addon/preview/passes.accumulate_pass without the lights' terms. Per pixel of this
 * pass's G-buffer (gbuffer_view = (ray direction, material)), Cycles' Principled Diffuse and
 * Glossy Color for the view (principled.glsl), and the gathered terms at the same texel
 * (centre_diffuse = (Diffuse Indirect, AO), centre_glossy = Glossy Indirect, centre_world =
 * the world's glossy light without the glossy colour: the centre pass's, or for a sub-pixel
 * pass upsample.glsl UPSAMPLE_TERMS's at its samples) are added to the sums
 * (sum_* in, out_* out; the pass count divides them at the end):
 *   a = (emission, coverage), b = (Diffuse Color, AO), c = (Glossy Color, holdout: the
 *   G-buffer's w = -1, a camera ray that met a holdout and shows nothing, gbuffer_frag.glsl),
 *   d = (Diffuse Color × Diffuse Indirect, 0), e = (Glossy Color × Glossy Indirect, 0),
 *   f = (glossy light, 0) += Glossy Color × centre_world.
 * out_colour = (Diffuse Color, 0) of this pass, for aa_light.glsl. Samplers: materials (base,
 * emission, (metallic, level, roughness) rows), principled_lut, gbuffer_base (the Base Color
 * sampled per texel where w > 0.5; where w > 1.5 also the emission per texel, packed by
 * textures.glsl's pack_emission). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_a);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 a = texelFetch(sum_a, px, 0);
  vec4 b = texelFetch(sum_b, px, 0);
  vec4 c = texelFetch(sum_c, px, 0);
  vec4 d = texelFetch(sum_d, px, 0);
  vec4 e = texelFetch(sum_e, px, 0);
  vec4 f = texelFetch(sum_f, px, 0);
  vec3 diffuse_colour = vec3(0.0);
  float w = texelFetch(gbuffer_position, px, 0).w;
  if (w < -0.5) {
    c.w += 1.0;
  }
  if (w > 0.5) {
    vec3 glossy_colour, emission;
    surface_colours(texelFetch(gbuffer_base, px, 0), texelFetch(gbuffer_normal, px, 0).xyz,
                    texelFetch(gbuffer_view, px, 0), diffuse_colour, glossy_colour, emission);
    vec4 gathered = texelFetch(centre_diffuse, px, 0);
    a += vec4(emission, 1.0);
    b += vec4(diffuse_colour, gathered.w);
    c.rgb += glossy_colour;
    d.rgb += diffuse_colour * gathered.rgb;
    e.rgb += glossy_colour * texelFetch(centre_glossy, px, 0).rgb;
    f.rgb += glossy_colour * texelFetch(centre_world, px, 0).rgb;
  }
  imageStore(out_a, px, a);
  imageStore(out_b, px, b);
  imageStore(out_c, px, c);
  imageStore(out_d, px, d);
  imageStore(out_e, px, e);
  imageStore(out_f, px, f);
  imageStore(out_colour, px, vec4(diffuse_colour, 0.0));
}

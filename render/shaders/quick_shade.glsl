/* The viewport's quick image, shown from the first draws after entering Rendered mode until
 * its first GI image (docs/gi_pipeline.md "Entering Rendered mode"): Solid-like shading of the
 * G-buffer alone, before the BVH, the lights or any tracing kernel are there. Each surface is
 * its material's Base Color (`palette` texel m = the materials texture's row 0, the material
 * index in gbuffer_view.w; variants past the palette take its last texel) lit by a headlight,
 * 0.25 + 0.75 |n · v|; elsewhere the world's mean colour. world: (rgb, alpha of the
 * background: 0 with Film › Transparent). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, position.w < -0.5 ? vec4(0.0) : world);
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec4 view = texelFetch(gbuffer_view, px, 0);
  int last = textureSize(palette, 0).x - 1;
  int m = clamp(int(view.w + 0.5), 0, last);
  vec3 base = texelFetch(palette, ivec2(m, 0), 0).rgb;
  float light = 0.25 + 0.75 * abs(dot(n, view.xyz));
  imageStore(out_image, px, vec4(base * light, 1.0));
}

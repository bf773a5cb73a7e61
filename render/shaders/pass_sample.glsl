/* One viewport sample's terms of one pass (voxgi_addon/preview/progressive.sample_terms) from
 * the GPU tracer's sums of one pass through the pixel centres (gpu_preview._accurate_stages,
 * count 1; their channels as preview.passes.SUMS: sum_a (emission, coverage), sum_b (Diffuse
 * Color, AO), sum_c (Glossy Color, holdout), sum_d Diffuse Indirect, sum_e Glossy Indirect,
 * sum_f Glossy Direct, sum_g Diffuse Direct, the light passes × their colour), as
 * preview.passes.finish_passes makes the passes:
 *   out_value  = (value, coverage), out_weight = (weight, holdout), out_light = (light, 0).
 * kind.x: 0 Combined, 1 Diffuse Direct, 2 Diffuse Indirect, 3 Glossy Direct, 4 Glossy
 * Indirect, 5 Diffuse Color, 6 Glossy Color, 7 Ambient Occlusion (PASS_KINDS). */

vec3 colour_times_ratio(vec3 light, vec3 colour)
{
  /* colour × (light / colour where colour > 0, else 0), per channel (finish_passes' ratio) */
  return vec3(colour.r > 0.0 ? colour.r * (light.r / colour.r) : 0.0,
              colour.g > 0.0 ? colour.g * (light.g / colour.g) : 0.0,
              colour.b > 0.0 ? colour.b * (light.b / colour.b) : 0.0);
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_value);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 a = texelFetch(sum_a, px, 0);
  vec4 b = texelFetch(sum_b, px, 0);
  vec4 c = texelFetch(sum_c, px, 0);
  vec3 di = texelFetch(sum_d, px, 0).rgb;
  vec3 gi = texelFetch(sum_e, px, 0).rgb;
  vec3 gd = texelFetch(sum_f, px, 0).rgb;
  vec3 dd = texelFetch(sum_g, px, 0).rgb;
  int k = int(kind.x + 0.5);
  vec3 value = vec3(0.0), weight = vec3(1.0), light = vec3(0.0);
  if (k == 0) {
    light = colour_times_ratio(di, b.rgb) + colour_times_ratio(gi, c.rgb);
    value = a.rgb + dd + di + gd + gi - light;
  }
  else if (k >= 1 && k <= 4) {
    vec3 colour = k <= 2 ? b.rgb : c.rgb;
    vec3 pass_light = k == 1 ? dd : (k == 2 ? di : (k == 3 ? gd : gi));
    value = colour_times_ratio(pass_light, colour);
    weight = colour;
  }
  else if (k == 5) {
    value = b.rgb;
  }
  else if (k == 6) {
    value = c.rgb;
  }
  else {
    value = vec3(b.a);
  }
  imageStore(out_value, px, vec4(value, a.a));
  imageStore(out_weight, px, vec4(weight, c.a));
  imageStore(out_light, px, vec4(light, 0.0));
}

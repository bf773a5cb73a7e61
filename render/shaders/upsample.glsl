/* Joint bilateral upsample of the reduced-resolution diffuse/AO image (gi_upsample.upsample,
 * ported line for line): per full-resolution pixel, the 3 × 3 traced cells around the nearest
 * one weighted by quadratic B-splines × max(n·n_k, 0)^8 ×
 * exp(−(|n·(p_k − p)| / (0.1·|p_k − p| + 1e-4))²); a pixel with
 * no usable neighbour takes the nearest traced cell within two cells.
 * sampling = (stride, full width, full height); low_image rows count from the bottom.
 * With UPSAMPLE_PAIR defined a second image (low_image2 → out_image2) is upsampled with the
 * same weights, its geometry fetched once. Taps of zero B-spline weight are skipped. */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 full = ivec2(sampling.yz);
  if (px.x >= full.x || px.y >= full.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
#ifdef UPSAMPLE_PAIR
    imageStore(out_image2, px, vec4(0.0));
#endif
    return;
  }
  int stride = int(sampling.x);
  ivec2 low = textureSize(low_image, 0);
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  float u = float(px.x - stride / 2) / float(stride);
  float v = float(full.y - 1 - px.y - stride / 2) / float(stride);
  int i0 = clamp(int(floor(u)), 0, low.x - 1);
  int j0 = clamp(int(floor(v)), 0, low.y - 1);
  /* Quadratic B-spline weights over the 3 × 3 cells around the nearest one. */
  int ci = int(floor(u + 0.5));
  int cj = int(floor(v + 0.5));
  float tu = u - float(ci);
  float tv = v - float(cj);
  vec3 wu = vec3(0.5 * (0.5 - tu) * (0.5 - tu), 0.75 - tu * tu, 0.5 * (0.5 + tu) * (0.5 + tu));
  vec3 wv = vec3(0.5 * (0.5 - tv) * (0.5 - tv), 0.75 - tv * tv, 0.5 * (0.5 + tv) * (0.5 + tv));
  vec4 total = vec4(0.0);
  vec4 total2 = vec4(0.0);
  float weight = 0.0;
  for (int dj = -1; dj <= 1; dj++) {
    for (int di = -1; di <= 1; di++) {
      float w = wu[di + 1] * wv[dj + 1];
      if (w <= 0.0) {
        continue;
      }
      int j = clamp(cj + dj, 0, low.y - 1);
      int i = clamp(ci + di, 0, low.x - 1);
      ivec2 q = traced_pixel(j, i, stride, full);
      vec4 pk = texelFetch(gbuffer_position, q, 0);
      vec3 nk = texelFetch(gbuffer_normal, q, 0).xyz;
      w *= pk.w > 0.5 ? 1.0 : 0.0;
      vec3 offset = pk.xyz - position.xyz;
      float facing = max(dot(n, nk), 0.0);
      float facing2 = facing * facing;
      float facing4 = facing2 * facing2;
      float plane = abs(dot(n, offset));
      float scale = 0.1 * length(offset) + 1e-4;
      w *= facing4 * facing4 * exp(-(plane / scale) * (plane / scale));
      total += w * texelFetch(low_image, ivec2(i, low.y - 1 - j), 0);
#ifdef UPSAMPLE_PAIR
      total2 += w * texelFetch(low_image2, ivec2(i, low.y - 1 - j), 0);
#endif
      weight += w;
    }
  }
  vec4 result = total / max(weight, 1e-30);
  vec4 result2 = total2 / max(weight, 1e-30);
  if (weight <= 1e-8) {
    float best = 1e30;
    result = vec4(0.0);
    result2 = vec4(0.0);
    for (int dj = -2; dj < 4; dj++) {
      for (int di = -2; di < 4; di++) {
        int j = clamp(j0 + dj, 0, low.y - 1);
        int i = clamp(i0 + di, 0, low.x - 1);
        float d = (float(dj) - 0.5) * (float(dj) - 0.5) + (float(di) - 0.5) * (float(di) - 0.5);
        if (texelFetch(gbuffer_position, traced_pixel(j, i, stride, full), 0).w > 0.5 && d < best) {
          result = texelFetch(low_image, ivec2(i, low.y - 1 - j), 0);
#ifdef UPSAMPLE_PAIR
          result2 = texelFetch(low_image2, ivec2(i, low.y - 1 - j), 0);
#endif
          best = d;
        }
      }
    }
  }
  imageStore(out_image, px, result);
#ifdef UPSAMPLE_PAIR
  imageStore(out_image2, px, result2);
#endif
}

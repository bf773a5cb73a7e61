/* One pass of the edge-aware à-trous filter (voxgi_addon/preview/denoise.py, ported line for
 * line) over the reduced-resolution gather: low_image holds (mean RGB, variance of the mean's
 * luminance); taps 2^i cells apart, B3-spline weights × same-surface terms (normal^32, plane)
 * × exp(−|Δluminance| / (4·√variance + 1e-6)). Variance is filtered with squared weights.
 * sampling = (stride, full width, full height, tap step); low_image rows count from the bottom. */
const float KERNEL[5] = float[5](1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);
const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);

void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  ivec2 low = textureSize(low_image, 0);
  if (cell.x >= low.x || cell.y >= low.y) {
    return;
  }
  int stride = int(sampling.x);
  ivec2 full = ivec2(sampling.yz);
  int step = int(sampling.w);
  vec4 centre = texelFetch(low_image, cell, 0);
  ivec2 px = traced_pixel(low.y - 1 - cell.y, cell.x, stride, full);
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, cell, centre);
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  float lum = dot(centre.rgb, LUMINANCE);
  float scale = 4.0 * sqrt(max(centre.a, 0.0)) + 1e-6;
  vec3 total = vec3(0.0);
  float total_var = 0.0;
  float weight = 0.0;
  for (int a = 0; a < 5; a++) {
    for (int b = 0; b < 5; b++) {
      ivec2 q = cell + ivec2(b - 2, a - 2) * step;
      if (q.x < 0 || q.y < 0 || q.x >= low.x || q.y >= low.y) {
        continue;
      }
      ivec2 qpx = traced_pixel(low.y - 1 - q.y, q.x, stride, full);
      vec4 pq = texelFetch(gbuffer_position, qpx, 0);
      if (pq.w < 0.5) {
        continue;
      }
      vec3 nq = texelFetch(gbuffer_normal, qpx, 0).xyz;
      vec4 vq = texelFetch(low_image, q, 0);
      vec3 offset = pq.xyz - position.xyz;
      float facing = pow(max(dot(n, nq), 0.0), 32.0);
      float plane = abs(dot(n, offset));
      float tol = 0.1 * length(offset) + 1e-4;
      float w = KERNEL[a] * KERNEL[b] * facing * exp(-(plane / tol) * (plane / tol));
      w *= exp(-abs(dot(vq.rgb, LUMINANCE) - lum) / scale);
      total += w * vq.rgb;
      total_var += w * w * vq.a;
      weight += w;
    }
  }
  if (weight > 0.0) {
    imageStore(out_image, cell, vec4(total / weight, total_var / (weight * weight)));
  }
  else {
    imageStore(out_image, cell, centre);
  }
}

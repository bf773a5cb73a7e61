/* One pass of the edge-aware à-trous filter (voxgi_addon/preview/denoise.py atrous_filter,
 * ported line for line) over the reduced-resolution gather. low_image = (light rgb, AO),
 * low_variance = (var of the light's luminance mean, var of the AO mean); taps 2^i cells apart,
 * B3-spline weights × same-surface terms (normal^32, plane) × per signal
 * exp(−|Δ| / (4·√(var_p + var_q) + 1e-6)), var_p the centre's variance prefiltered over 3 × 3
 * valid cells, var_q the tap's own (why both: denoise.py).
 * Variances are filtered with squared weights. A cell whose prefiltered standard error is
 * within NOISE_TARGET of its value is settled: kept as it is (denoise.py NOISE_TARGET).
 * grid = (stride, full width, full height, tap step); low-resolution rows count from the bottom. */
const float KERNEL[5] = float[5](1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);
const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);

void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  ivec2 low = textureSize(low_image, 0);
  if (cell.x >= low.x || cell.y >= low.y) {
    return;
  }
  int stride = int(grid.x);
  ivec2 full = ivec2(grid.yz);
  int step = int(grid.w);
  vec4 centre = texelFetch(low_image, cell, 0);
  vec4 centre_var = texelFetch(low_variance, cell, 0);
  ivec2 px = traced_pixel(low.y - 1 - cell.y, cell.x, stride, full);
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, cell, centre);
    imageStore(out_variance, cell, centre_var);
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec2 signal = vec2(dot(centre.rgb, LUMINANCE), centre.a);
  /* The variance prefiltered over the valid 3 × 3 neighbours (denoise.py _blurred). */
  vec2 blurred = vec2(0.0);
  float blur_weight = 0.0;
  for (int a = -1; a <= 1; a++) {
    for (int b = -1; b <= 1; b++) {
      ivec2 q = cell + ivec2(b, a);
      if (q.x < 0 || q.y < 0 || q.x >= low.x || q.y >= low.y) {
        continue;
      }
      if (texelFetch(gbuffer_position, traced_pixel(low.y - 1 - q.y, q.x, stride, full), 0).w < 0.5) {
        continue;
      }
      float g = (a == 0 ? 0.5 : 0.25) * (b == 0 ? 0.5 : 0.25);
      blurred += g * texelFetch(low_variance, q, 0).xy;
      blur_weight += g;
    }
  }
  blurred /= max(blur_weight, 1e-30);
  bvec2 settled = lessThanEqual(sqrt(max(blurred, vec2(0.0))), NOISE_TARGET * abs(signal));
  vec4 total = vec4(0.0);
  vec2 total_var = vec2(0.0);
  vec2 weight = vec2(0.0);
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
      vec2 varq = texelFetch(low_variance, q, 0).xy;
      vec3 offset = pq.xyz - position.xyz;
      float facing = pow(max(dot(n, nq), 0.0), 32.0);
      float plane = abs(dot(n, offset));
      float tol = 0.1 * length(offset) + 1e-4;
      float geometry = KERNEL[a] * KERNEL[b] * facing * exp(-(plane / tol) * (plane / tol));
      vec2 scale = 4.0 * sqrt(max(blurred + varq, vec2(0.0))) + 1e-6;
      vec2 w = geometry * exp(-abs(vec2(dot(vq.rgb, LUMINANCE), vq.a) - signal) / scale);
      total += vec4(w.x * vq.rgb, w.y * vq.a);
      total_var += w * w * varq;
      weight += w;
    }
  }
  vec4 result = centre;
  vec2 result_var = centre_var.xy;
  if (weight.x > 0.0 && !settled.x) {
    result.rgb = total.rgb / weight.x;
    result_var.x = total_var.x / (weight.x * weight.x);
  }
  if (weight.y > 0.0 && !settled.y) {
    result.a = total.a / weight.y;
    result_var.y = total_var.y / (weight.y * weight.y);
  }
  imageStore(out_image, cell, result);
  imageStore(out_variance, cell, vec4(result_var, 0.0, 0.0));
}

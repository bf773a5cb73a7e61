/* Probe bake, pass 2: SH L2 projection (voxgi_addon/probes/sh.py project) of pass 1's radiance.
 * out pixel (x, y): probe y·64 + x / 9, coefficient x % 9 (Sloan's order); value rgb =
 * 4π/N Σ_i L(probe, i) Y_k(dir_i). probe_radiance: pass 1's image (pair = y·width + x);
 * sampling = (N, P, radiance image width, 0). */
float sh_basis(int k, vec3 d)
{
  switch (k) {
    case 0: return 0.28209479177387814;
    case 1: return 0.4886025119029199 * d.y;
    case 2: return 0.4886025119029199 * d.z;
    case 3: return 0.4886025119029199 * d.x;
    case 4: return 1.0925484305920792 * d.x * d.y;
    case 5: return 1.0925484305920792 * d.y * d.z;
    case 6: return 0.31539156525252005 * (3.0 * d.z * d.z - 1.0);
    case 7: return 1.0925484305920792 * d.x * d.z;
    default: return 0.5462742152960396 * (d.x * d.x - d.y * d.y);
  }
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  int n = int(sampling.x);
  int width = int(sampling.z);
  int probe = px.y * 64 + px.x / 9;
  int k = px.x % 9;
  if (probe >= int(sampling.y)) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 sum = vec3(0.0);
  for (int i = 0; i < n; i++) {
    int pair = probe * n + i;
    vec3 l = texelFetch(probe_radiance, ivec2(pair % width, pair / width), 0).rgb;
    sum += l * sh_basis(k, texelFetch(probe_dirs, ivec2(i, 0), 0).xyz);
  }
  imageStore(out_image, px, vec4(sum * (4.0 * 3.14159265358979 / float(n)), 0.0));
}

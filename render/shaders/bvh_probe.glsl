/* Test kernel: one ray per texel. ray_origin = (o.xyz, tmin), ray_direction = (d.xyz, tmax).
 * mode.x = 0: closest hit, out = (t or -1, SceneTriangles index or -1, u, v);
 * mode.x = 1: any hit (bvh_any_hit with tmax, the shadow-ray convention), out = (hit, 0, 0, 0);
 * mode.x = 2: sample patterns of texel id k (row-major from the bottom), out =
 *   (unit_float(pcg_hash(k)), hashed_stratum(point_stream(k, 3, 0), 5, 4), hammersley(k's
 *   stream 0, point 3 of 8).x). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 o = texelFetch(ray_origin, px, 0);
  vec4 d = texelFetch(ray_direction, px, 0);
  vec4 result = vec4(0.0);
  if (mode.x < 0.5) {
    float t;
    int triangle, slot;
    vec2 uv;
    if (bvh_closest_hit(o.xyz, d.xyz, o.w, d.w, t, triangle, slot, uv)) {
      result = vec4(t, float(triangle), uv);
    }
    else {
      result = vec4(-1.0, -1.0, 0.0, 0.0);
    }
  }
  else if (mode.x < 1.5) {
    result = vec4(bvh_any_hit(o.xyz, d.xyz, d.w) ? 1.0 : 0.0, 0.0, 0.0, 0.0);
  }
  else {
    uint k = uint(px.y * size.x + px.x);
    result = vec4(unit_float(pcg_hash(k)), hashed_stratum(point_stream(k, 3u, 0u), 5, 4),
                  hammersley(point_stream(k, 0u, 0u), 3, 8).x);
  }
  imageStore(out_image, px, result);
}

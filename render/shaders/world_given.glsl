/* F12's pixel centres' world light where the rest of the world's light hidden from them is
 * given (world_hidden: the diffuse gather's, filtered and upsampled; docs/gi_pipeline.md "The
 * world's light at the gather points") and nothing else of the world's and emitters' dispatch
 * traces a ray (a uniform world or a map without a sun, no emitters): the world's exact
 * unshadowed Diffuse Direct at the pixel's normal less it, as bvh_lights.glsl
 * world_direct_lobe's given path computes it. A kernel of its own: bvh_direct.glsl pays about
 * 3 µs of llvmpipe's set-up a row of eight invocations for its size, whatever they do (57 ms
 * over 640 × 480 with no work at all; this kernel 1–2 ms). out_image = (rgb, 0: no variance). */
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  if (texelFetch(gbuffer_position, px, 0).w < 0.5 || !world_on()) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 value = world_unshadowed(texelFetch(gbuffer_normal, px, 0).xyz, int(world_header().x));
  vec3 hidden = texelFetch(world_hidden, px, 0).rgb;
  imageStore(out_image, px, vec4(max(value - hidden, vec3(0.0)), 0.0));
}

/* The edge pixels of one sub-pixel pass as a compact list (preview/passes.adaptive_passes):
 * texel t of the outputs is the pixel pixels[t] = (x, y, id, 1) (GL coordinates, id = its
 * index in the image, row 0 on top; (0, 0, 0, 0) pads the list). Copies the pass's G-buffer
 * there, position.w = 2 + id where the pixel sees a surface (0 where not), so bvh_direct.glsl
 * and glossy_direct.glsl draw that pixel's samples, and the other kernels of the pass
 * (aa_surface, aa_light) see a hit as before (w > 0.5). With RAW defined, copies the three
 * inputs unchanged (the centre pass's gathered terms for the same list). A dispatch over the
 * list instead of over the image: llvmpipe spends as long on a pixel that returns early from
 * the shadow-ray kernels as on a few of its rays. */

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_position);
  if (t.x >= size.x || t.y >= size.y) {
    return;
  }
  vec4 pixel = texelFetch(pixels, t, 0);
  if (pixel.w < 0.5) {
    imageStore(out_position, t, vec4(0.0));
    imageStore(out_normal, t, vec4(0.0));
    imageStore(out_view, t, vec4(0.0));
    return;
  }
  ivec2 px = ivec2(pixel.xy + 0.5);
  vec4 position = texelFetch(gbuffer_position, px, 0);
#ifndef RAW
  position.w = position.w > 0.5 ? 2.0 + pixel.z : min(position.w, 0.0); /* -1: a holdout */
#endif
  imageStore(out_position, t, position);
  imageStore(out_normal, t, texelFetch(gbuffer_normal, px, 0));
  imageStore(out_view, t, texelFetch(gbuffer_view, px, 0));
}

/* List entries written at their places in an image (render/gpu_tails.py): entry t of the list
 * places = (x, y, …, 1) (GL coordinates; w < 0.5 pads the list, nothing written) goes to the
 * texel (x, y).
 *
 * INDEX defined (kernel aa_index): places is the edge pixels' list (x, y, id, 1) and out_index
 * at (x, y) = 1 + t's index in the list (row major, the list's width wide); the image is
 * cleared to 0 before (no edge pixel there).
 * Else (aa_place): the sub-pixel samples that their pass shaded (not resolved from the
 * centres), sum_a … sum_g of the list's size, written into their raster's samples out_a …
 * out_g as aa_resolve.glsl wrote them. */

void main()
{
  ivec2 t = ivec2(gl_GlobalInvocationID.xy);
  ivec2 list = textureSize(places, 0);
  if (t.x >= list.x || t.y >= list.y) {
    return;
  }
  vec4 place = texelFetch(places, t, 0);
  if (place.w < 0.5) {
    return;
  }
  ivec2 at = ivec2(place.xy + 0.5);
#ifdef INDEX
  imageStore(out_index, at, vec4(float(t.y * list.x + t.x + 1)));
#else
  imageStore(out_a, at, texelFetch(sum_a, t, 0));
  imageStore(out_b, at, texelFetch(sum_b, t, 0));
  imageStore(out_c, at, texelFetch(sum_c, t, 0));
  imageStore(out_d, at, texelFetch(sum_d, t, 0));
  imageStore(out_e, at, texelFetch(sum_e, t, 0));
  imageStore(out_f, at, texelFetch(sum_f, t, 0));
  imageStore(out_g, at, texelFetch(sum_g, t, 0));
#endif
}

/* The sub-pixel passes' test against their pixel's centre (voxgi_addon/preview/passes.py
 * same_surface): samplers centre_position, centre_normal, centre_view hold the pixel centres'
 * G-buffer at the same texels as the pass's (aa_compact.glsl over the edge pixels' list, or
 * the centres' own G-buffer for the centre pass; upsample.glsl UPSAMPLE_TERMS defines the
 * names as its full-resolution gbuffer_* and reads them at the list entry's pixel). Needs
 * PLANE_TOLERANCE. */

/* whether the pass's point (position, normal, material: it sees a surface) lies on the surface
 * the centre sees at texel px */
bool same_surface(vec4 position, vec3 normal, float material, ivec2 px)
{
  vec4 centre = texelFetch(centre_position, px, 0);
  if (centre.w < 0.5 || int(material + 0.5) != int(texelFetch(centre_view, px, 0).w + 0.5)) {
    return false;
  }
  vec3 step = position.xyz - centre.xyz;
  float off_plane = max(abs(dot(texelFetch(centre_normal, px, 0).xyz, step)),
                        abs(dot(normal, step)));
  return off_plane <= PLANE_TOLERANCE * length(step);
}

/* A G-buffer texel's surface as the composition reads it (aa_surface.glsl, aa_resolve.glsl):
 * its material (gbuffer_view.w, clamped to the table's last row: the fallback material), its
 * Base Color (gbuffer_base's texel where w > 0.5: per texel, else the material's), its
 * emission (the material's, or per texel where w > 1.5: textures.glsl's pack_emission) and
 * Cycles' Principled Diffuse and Glossy Color seen along the ray `ray` (principled.glsl).
 * Needs the samplers `materials` and `principled_lut`. */
void surface_colours(vec4 texel, vec3 n, vec4 ray, out vec3 diffuse_colour,
                     out vec3 glossy_colour, out vec3 emission)
{
  int last_material = textureSize(materials, 0).x - 1;
  int material = int(ray.w + 0.5);
  material = (material >= 0 && material < last_material) ? material : last_material;
  vec3 base = texel.w > 0.5 ? texel.rgb : texelFetch(materials, ivec2(material, 0), 0).rgb;
  emission = texelFetch(materials, ivec2(material, 1), 0).rgb;
  if (texel.w > 1.5) {  /* emission per texel (textures.glsl pack_emission) */
    uint bits = floatBitsToUint(texel.w) - 0x40000000u;
    emission = vec3(uvec3(bits >> 16, bits >> 8, bits) & uvec3(255u)) *
               exp2(float(int(bits >> 24) - 15) - 8.0);
  }
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
  float mu = clamp(dot(n, -ray.xyz), 0.0, 1.0);
  diffuse_colour = principled_diffuse_weight(base, params.x, params.y, params.z, mu);
  glossy_colour = principled_glossy_color(base, params.x, params.y, params.z, mu);
}

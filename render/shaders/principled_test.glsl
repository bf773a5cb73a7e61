/* Test kernel of principled.glsl (render/gpu_principled.py evaluate): one input per texel,
 * in_material = (base.rgb, metallic), in_params = (specular IOR level, roughness, -, -),
 * in_normal / in_view / in_light = (unit vector, -), in_irradiance = (rgb, -). */

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 material = texelFetch(in_material, px, 0);
  vec4 params = texelFetch(in_params, px, 0);
  vec3 n = texelFetch(in_normal, px, 0).xyz;
  vec3 v = texelFetch(in_view, px, 0).xyz;
  vec3 l = texelFetch(in_light, px, 0).xyz;
  vec3 e = texelFetch(in_irradiance, px, 0).xyz;
  float mu = dot(n, v);
  imageStore(out_image, px,
             vec4(principled_diffuse_weight(material.rgb, material.a, params.x, params.y, mu), 1.0));
  imageStore(out_glossy_color, px,
             vec4(principled_glossy_color(material.rgb, material.a, params.x, params.y, mu), 1.0));
  imageStore(out_reflectance, px,
             vec4(principled_glossy_reflectance(material.rgb, material.a, params.x, params.y, n, v, l),
                  1.0));
  imageStore(out_radiance, px,
             vec4(principled_outgoing_radiance(material.rgb, material.a, params.x, params.y, n, v, l,
                                               e), 1.0));
}

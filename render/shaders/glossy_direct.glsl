/* The glossy light one light sends to the viewer (Glossy Color × Glossy Direct) per G-buffer
 * pixel: the port of voxgi_addon/preview/passes.glossy_direct_radiance for light `light.x`.
 * Its shadowed Diffuse Direct (direct_image, that light alone) is turned back into irradiance
 * (× π) and spread over the light's directions — one for suns and point lights, the centres of
 * a 4 × 4 grid over an area light (inside the ellipse for round ones), weighted by their share
 * of the unshadowed irradiance — each reflected toward the viewer by the Principled glossy
 * lobe (principled.glsl) / cos. Samplers: lights (preview/light_table.py), materials (base,
 * emission, (metallic, level, roughness) rows), principled_lut; gbuffer_view = (ray direction,
 * material). */
#define AREA_GLOSSY_GRID 4

vec4 glossy_light_texel(int k)
{
  return texelFetch(lights, ivec2(k, int(light.x)), 0);
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  vec3 direct = texelFetch(direct_image, px, 0).rgb;
  vec4 head = glossy_light_texel(0);
  if (position.w < 0.5 || head.x < 0.0 || dot(direct, vec3(1.0)) <= 0.0) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec4 ray = texelFetch(gbuffer_view, px, 0);
  vec3 view = -ray.xyz;
  int last_material = textureSize(materials, 0).x - 1;
  int material = int(ray.w + 0.5);
  material = (material >= 0 && material < last_material) ? material : last_material;
  vec3 base = texelFetch(materials, ivec2(material, 0), 0).rgb;
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
  int kind = int(head.x);
  vec3 lobe = vec3(0.0);
  if (kind != 3) {
    vec3 towards = kind == 0 ? -glossy_light_texel(5).xyz :
                               normalize(glossy_light_texel(2).xyz - position.xyz);
    float c = dot(n, towards);
    if (c > 1e-4) {
      lobe = principled_glossy_reflectance(base, params.x, params.y, params.z, n, view, towards) / c;
    }
  }
  else {
    vec3 centre = glossy_light_texel(2).xyz;
    vec3 ex = glossy_light_texel(3).xyz;
    vec3 ey = glossy_light_texel(4).xyz;
    vec3 emits = glossy_light_texel(5).xyz;
    bool round_shape = head.y > 0.5;
    float total = 0.0;
    for (int j = 0; j < AREA_GLOSSY_GRID; j++) {
      for (int i = 0; i < AREA_GLOSSY_GRID; i++) {
        float u = 2.0 * ((float(i) + 0.5) / float(AREA_GLOSSY_GRID) - 0.5);
        float v = 2.0 * ((float(j) + 0.5) / float(AREA_GLOSSY_GRID) - 0.5);
        if (round_shape && u * u + v * v > 1.0) {
          continue;
        }
        vec3 offset = centre + u * ex + v * ey - position.xyz;
        float distance = max(length(offset), 1e-9);
        vec3 towards = offset / distance;
        float c = dot(n, towards);
        float weight = max(-dot(towards, emits), 0.0) * max(c, 0.0) / (distance * distance);
        total += weight;
        if (c > 1e-4) {
          lobe += weight *
                  principled_glossy_reflectance(base, params.x, params.y, params.z, n, view,
                                                towards) / c;
        }
      }
    }
    lobe /= max(total, 1e-30);
  }
  imageStore(out_image, px, vec4(direct * 3.14159265358979323846 * lobe, 1.0));
}

/* The glossy light one light sends to the viewer (Glossy Color × Glossy Direct) per G-buffer
 * pixel: the port of voxgi_addon/preview/passes.glossy_direct_radiance for light `light.x`.
 * Its shadowed Diffuse Direct (direct_image, that light alone) is turned back into irradiance
 * (× π) and spread over the light's directions — one for suns and point lights, 4 × 4 strata
 * over an area light (centres, jittered with the pixel's hash stream GLOSSY_LIGHT_STREAM +
 * light index as far as passes.glossy_jitter says, mapped as the shadow rays map theirs:
 * sampling.glsl), weighted by their share of the unshadowed
 * irradiance — each reflected toward the viewer by the Principled glossy lobe (principled.glsl)
 * / cos. Samplers: lights (preview/light_table.py), materials (base, emission, (metallic, level,
 * roughness) rows), principled_lut; gbuffer_view = (ray direction, material); gbuffer_base =
 * (Base Color per texel, 1) where textured. */

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
  vec4 texel = texelFetch(gbuffer_base, px, 0);  /* Base Color per texel (G-buffer) */
  vec3 base = texel.w > 0.5 ? texel.rgb : texelFetch(materials, ivec2(material, 0), 0).rgb;
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
    uint id = position.w > 1.5 ? uint(position.w) - 2u  /* a listed pixel: aa_compact.glsl */
                               : uint((size.y - 1 - px.y) * size.x + px.x);
    uint state = point_stream(id, GLOSSY_LIGHT_STREAM + uint(light.x), 0u);
    /* passes.glossy_jitter: strata centres while the lobe is wider than a stratum */
    float alpha = clamp(params.z, 0.0, 1.0) * clamp(params.z, 0.0, 1.0);
    float extent = 2.0 * max(length(ex), length(ey));
    float spacing = extent / max(length(centre - position.xyz), 1e-9) / float(AREA_GLOSSY_GRID);
    float amount = clamp(spacing / max(2.0 * alpha, 1e-6) - 1.0, 0.0, 1.0);
    for (int k = 0; k < AREA_GLOSSY_GRID * AREA_GLOSSY_GRID; k++) {
      vec2 mid = (vec2(float(k / AREA_GLOSSY_GRID), float(k % AREA_GLOSSY_GRID)) + 0.5) /
                 float(AREA_GLOSSY_GRID);
      vec2 s = mid + amount * (hashed_stratum(state, k, AREA_GLOSSY_GRID) - mid);
      vec2 unit = round_shape ? concentric_disk(s) : s * 2.0 - 1.0;
      vec3 offset = centre + unit.x * ex + unit.y * ey - position.xyz;
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
    lobe /= max(total, 1e-30);
  }
  imageStore(out_image, px, vec4(direct * 3.14159265358979323846 * lobe, 1.0));
}

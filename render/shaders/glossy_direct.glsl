/* The glossy light one lamp sends to the viewer (Glossy Color × Glossy Direct) per G-buffer
 * pixel, without noise: the port of voxgi_addon/preview/passes.glossy_direct_radiance for lamp
 * `light.x`. Its shadowed Diffuse Direct (direct_image, that lamp alone) is turned back into
 * irradiance (× π) and reflected toward the viewer by the Principled glossy lobe
 * (principled.glsl) / cos: from a sun's or a point light's direction, and, as far as
 * passes.disc_share says (a lobe narrow against the lamp's disc), by the lobe's mean over the
 * disc a point or spot light of some radius or a sun of some angle shows (disc_shine); from an
 * area lamp's AREA_GLOSSY_GRID² strata centres (mapped as the shadow rays map theirs:
 * sampling.glsl), weighted by their share of its unshadowed irradiance, and, as far as
 * passes.ltc_share says (a reflection that few strata hold), by the lobe integrated over the
 * lamp by LTC (glossy_ltc.glsl area_glossy) × the share of its unshadowed light that
 * direct_image holds (light_outline.glsl polygon_irradiance), as a bounce hit's metal lobe
 * takes it (bvh_shade.glsl; exact_glossy.area_shine).
 * The pixel's footprint (preview/lobe_footprint.py) widens an area lamp's lobe (to the
 * G-buffer's normal.w) and a round lamp's disc (disc_growth). light = (row of the lamp in
 * `lights`, 1 for the map's sun: 0 on a mirror, passes.map_sun_shine).
 * Samplers: lights (preview/light_table.py), materials (base, emission, (metallic, level,
 * roughness) rows), principled_lut, ltc_table; gbuffer_view = (ray direction, material);
 * gbuffer_base = (Base Color per texel, 1) where textured. */

vec4 light_texel(int light, int k)
{
  return texelFetch(lights, ivec2(k, light), 0);
}

/* exact_glossy.disc_shine: direct × π × the lobe's mean over the disc of `radius` at `middle`
 * (facing along `axis`), ∫ f cos dω / ∫ cos dω — the LTC integral of the lobe with its Fresnel
 * over the disc's DISC_SIDES-gon (glossy_ltc_triangle) over Lambert's formula (the LTC with
 * M^-1 the identity), both clipped to the horizon; 0 for a mirror, a view below the horizon
 * or a disc below it. */
vec3 disc_shine(vec3 direct, vec3 middle, vec3 axis, float radius, vec3 p, vec3 n, vec3 v,
                vec3 base, vec3 params)
{
  GlossyLobe g;
  LtcLobe lobe;
  vec3 white_colour;
  if (!polygon_lobe(n, v, base, params, g, lobe, white_colour)) {
    return vec3(0.0);
  }
  vec3 t, b;
  perpendicular_basis(axis, t, b);
  float step = 2.0 * 3.14159265358979323846 / float(DISC_SIDES);
  vec3 c0 = middle + radius * t;
  vec3 previous = middle + radius * (cos(step) * t + sin(step) * b);
  vec3 sum = vec3(0.0);
  vec3 lambert = vec3(0.0);
  for (int k = 2; k < DISC_SIDES; k++) {
    vec3 next = middle + radius * (cos(step * float(k)) * t + sin(step * float(k)) * b);
    sum += glossy_ltc_triangle(lobe, g, p, n, v, c0, previous, next, white_colour);
    lambert += ltc_clipped_triangle(lobe.to_local * (c0 - p), lobe.to_local * (previous - p),
                                    lobe.to_local * (next - p), vec4(1.0, 0.0, 1.0, 0.0));
    previous = next;
  }
  float cosine = abs(lambert.z) / (2.0 * 3.14159265358979323846);  /* ∫ cos θ / π dω */
  return cosine > 0.0 ? direct * sum * white_colour / cosine : vec3(0.0);
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  int lamp = int(light.x);
  vec4 position = texelFetch(gbuffer_position, px, 0);
  vec3 direct = texelFetch(direct_image, px, 0).rgb;
  vec4 head = light_texel(lamp, 0);
  if (position.w < 0.5 || head.x < 0.0 || dot(direct, vec3(1.0)) <= 0.0) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec4 normal = texelFetch(gbuffer_normal, px, 0);
  vec3 n = normal.xyz;
  vec4 ray = texelFetch(gbuffer_view, px, 0);
  vec3 view = -ray.xyz;
  int last_material = textureSize(materials, 0).x - 1;
  int material = int(ray.w + 0.5);
  material = (material >= 0 && material < last_material) ? material : last_material;
  vec4 texel = texelFetch(gbuffer_base, px, 0);  /* Base Color per texel (G-buffer) */
  vec3 base = texel.w > 0.5 ? texel.rgb : texelFetch(materials, ivec2(material, 0), 0).rgb;
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
  /* the pixel's footprint (preview/lobe_footprint.py; the G-buffer's normal.w is the lobe's
   * roughness widened by it) widens an area lamp's lobe and a round lamp's disc (disc_growth) */
  float own = clamp(params.z, 0.0, 1.0);
  float widened = clamp(normal.w, 0.0, 1.0);
  float grow = 8.0 * max(widened * widened * widened * widened - own * own * own * own, 0.0);
  if (light.y > 0.5 && own * own * own * own <= PR_ROUGHNESS_SQ_THRESHOLD) {
    /* the map's sun on a mirror: its one ray in the world's glossy gather sees it
     * (passes.map_sun_shine) */
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 shine = vec3(0.0);
  if (int(head.x) != 3) {
    vec3 towards = int(head.x) == 0 ? -light_texel(lamp, 5).xyz :
                                      normalize(light_texel(lamp, 2).xyz - position.xyz);
    float c = dot(n, towards);
    if (c > 1e-4) {
      shine = direct * (3.14159265358979323846 / c) *
              principled_glossy_reflectance(base, params.x, params.y, params.z, n, view, towards);
    }
    /* a round lamp's disc (exact_glossy.round_lamp_disc): the lobe's mean over it as far as
     * passes.disc_share says */
    vec3 middle, axis;
    float radius;
    bool shows;
    if (int(head.x) == 0) {
      axis = -light_texel(lamp, 5).xyz;
      middle = position.xyz + axis;
      radius = light_texel(lamp, 3).w;
      shows = radius > 0.0 || grow > 0.0;
    }
    else {
      float r = light_texel(lamp, 2).w;
      vec3 offset = light_texel(lamp, 2).xyz - position.xyz;
      float d = max(length(offset), 1e-30);
      axis = offset / d;
      shows = (r > 0.0 || grow > 0.0) && d > r * (1.0 + 1e-6);
      float inside = max(d * d - r * r, 0.0);
      middle = position.xyz + axis * (inside / d);
      radius = r * sqrt(inside) / d;
    }
    if (shows) {
      float rough = own;
      float distance = max(length(middle - position.xyz), 1e-30);
      float angular = atan(radius, distance);
      angular = min(sqrt(angular * angular + grow), DISC_WIDEST);
      radius = distance * tan(angular);
      float share = clamp((angular / max(2.0 * rough * rough, 1e-6) - DISC_FROM) /
                          (DISC_FULL - DISC_FROM), 0.0, 1.0);
      if (share > 0.0) {
        vec3 mean = disc_shine(direct, middle, axis, radius, position.xyz, n, view, base, params);
        if (any(notEqual(mean, vec3(0.0)))) {
          shine = mix(shine, mean, share);
        }
      }
    }
  }
  else {
    params.z = widened;
    vec3 centre = light_texel(lamp, 2).xyz;
    vec3 ex = light_texel(lamp, 3).xyz;
    vec3 ey = light_texel(lamp, 4).xyz;
    vec3 emits = light_texel(lamp, 5).xyz;
    bool round_shape = head.y > 0.5;
    float total = 0.0, squares = 0.0, first = 0.0, second = 0.0;
    vec3 lobe = vec3(0.0);
    for (int k = 0; k < AREA_GLOSSY_GRID * AREA_GLOSSY_GRID; k++) {
      vec2 s = (vec2(float(k / AREA_GLOSSY_GRID), float(k % AREA_GLOSSY_GRID)) + 0.5) /
               float(AREA_GLOSSY_GRID);
      vec2 unit = round_shape ? concentric_disk(s) : s * 2.0 - 1.0;
      vec3 offset = centre + unit.x * ex + unit.y * ey - position.xyz;
      float distance = max(length(offset), 1e-9);
      vec3 towards = offset / distance;
      float c = dot(n, towards);
      float weight = max(-dot(towards, emits), 0.0) * max(c, 0.0) / (distance * distance);
      total += weight;
      squares += weight * weight;
      if (c > 1e-4) {
        vec3 term = weight * principled_glossy_reflectance(base, params.x, params.y, params.z,
                                                           n, view, towards) / c;
        lobe += term;
        float t = dot(term, LUMA);
        first += t;
        second += t * t;
      }
    }
    shine = direct * 3.14159265358979323846 * lobe / max(total, 1e-30);
    /* passes.ltc_share: the centres while the reflection spreads over LTC_FROM strata or more,
     * the integral alone from LTC_FULL down (the terms' effective count over the shares') */
    float count = second > 0.0 && squares > 0.0 ?
                  float(AREA_GLOSSY_GRID * AREA_GLOSSY_GRID) * (first * first / second) /
                  (total * total / squares) : LTC_FROM;
    float share = clamp((LTC_FROM - count) / (LTC_FROM - LTC_FULL), 0.0, 1.0);
    if (share > 0.0) {
      vec3 integral = vec3(0.0);
      vec3 aim;
      float unshadowed = polygon_irradiance(lamp, int(head.z), position.xyz, n, aim) *
                         light_texel(lamp, 6).y * dot(light_texel(lamp, 1).rgb, LUMA);
      float lit = dot(direct, LUMA);
      if (unshadowed > 0.0 && lit > 0.0) {
        integral = clamp(lit / unshadowed, 0.0, 1.0) *
                   area_glossy(lamp, int(head.z), position.xyz, n, view, base, params);
      }
      shine = mix(shine, integral, share);
    }
  }
  imageStore(out_image, px, vec4(shine, 1.0));
}

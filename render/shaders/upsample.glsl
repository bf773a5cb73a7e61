/* Joint bilateral upsample of the reduced-resolution diffuse/AO image (gi_upsample.upsample,
 * ported line for line): per full-resolution pixel, the 3 × 3 traced cells around the nearest
 * one weighted by quadratic B-splines × max(n·n_k, 0)^8 ×
 * exp(−(|n·(p_k − p)| / (0.1·|p_k − p| + 1e-4))²); a pixel with
 * no usable neighbour takes the nearest traced cell within two cells.
 * sampling = (stride, full width, full height); low_image rows count from the bottom.
 * With UPSAMPLE_PAIR defined a second image (low_image2 → out_image2) is upsampled with the
 * same weights, its geometry fetched once. Taps of zero B-spline weight are skipped.
 *
 * UPSAMPLE_FIELD (with UPSAMPLE_PAIR): the emitters' light (docs/gi_pipeline.md "Where a
 * preview's time goes"; preview/upsample.py EmitterField): low_image = their glossy light
 * over the Glossy Color, low_image2 = (their unshadowed Diffuse Direct, the distance from the
 * gather point to the nearest emissive triangle that can light it). The outputs' w is how far
 * the light's direction turns across the taps, in radians, the root mean square over them by
 * their weights: out_image2.w of the step to a tap over the distance left to the emitters
 * beyond it (the distance is 1-Lipschitz, so they lie at least d_k − |p_k − p| away) + the
 * normal's turn (|n − n_k|), for the cosine lobe; out_image.w of that + the view direction's
 * turn (|p_k − p| / the camera's distance, eye = (camera position, 1), or (0, 0, 0, 0)
 * orthographic) + the normal's again (a mirror turns its reflection twice as far), for the
 * glossy lobe; −1 where no tap weighs (then the rgb is 0). The kernels that read it
 * evaluate the light themselves where the angle is beyond NEAR_STEP of their lobe's width. At
 * stride 1 (no UPSAMPLE_LIST) the field is copied with w = 0: it is every pixel's own.
 * UPSAMPLE_LIST (with UPSAMPLE_FIELD): the points are a sub-pixel pass's samples over the edge
 * pixels' list (aa_compact.glsl): texel t reads pixels[t] = (x, y, id, 1) and the pass's
 * compacted G-buffer point_position, point_normal, and sits at that pixel + shift.xy (the
 * pass's offset, x right, y down); the taps stay the pixel centres' G-buffer.
 * UPSAMPLE_TERMS (with UPSAMPLE_LIST, with or without UPSAMPLE_FIELD): also the gathered terms
 * at the pass's samples (docs/gi_pipeline.md "Anti-aliasing"; preview/upsample.py upsample_at):
 * low_diffuse, low_glossy, low_world (the gather points' (Diffuse Indirect, AO), Glossy
 * Indirect, world glossy light; low_image's grid) → out_diffuse, out_glossy, out_world with the
 * same weights where the sample sees another surface than its pixel's centre (same_surface.glsl
 * against the centres' full-resolution G-buffer at pixel.xy, point_view.w = the sample's
 * material; the centre_* names are defined as the gbuffer_* ones), else — or where no tap
 * weighs — the centre's own full_diffuse, full_glossy, full_world at pixel.xy. */
#if !defined(UPSAMPLE_TERMS) || defined(UPSAMPLE_FIELD)
#  define UPSAMPLE_IMAGE /* low_image → out_image */
#  define LOW_GRID low_image
#  define FIRST_OUT out_image
#else
#  define LOW_GRID low_diffuse
#  define FIRST_OUT out_diffuse
#endif
void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 full = ivec2(sampling.yz);
  int stride = int(sampling.x);
#ifdef UPSAMPLE_LIST
  ivec2 size = imageSize(FIRST_OUT);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 pixel = texelFetch(pixels, px, 0);
  vec4 position = texelFetch(point_position, px, 0);
  if (pixel.w < 0.5 || position.w < 0.5) {
#  ifdef UPSAMPLE_TERMS
    imageStore(out_diffuse, px, vec4(0.0));
    imageStore(out_glossy, px, vec4(0.0));
    imageStore(out_world, px, vec4(0.0));
#  endif
#else
  if (px.x >= full.x || px.y >= full.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
#endif
#ifdef UPSAMPLE_IMAGE
    imageStore(out_image, px, vec4(0.0));
#endif
#ifdef UPSAMPLE_PAIR
    imageStore(out_image2, px, vec4(0.0));
#endif
    return;
  }
#if defined(UPSAMPLE_FIELD) && !defined(UPSAMPLE_LIST)
  if (stride == 1) {
    imageStore(out_image, px, vec4(texelFetch(low_image, px, 0).rgb, 0.0));
    imageStore(out_image2, px, vec4(texelFetch(low_image2, px, 0).rgb, 0.0));
    return;
  }
#endif
  ivec2 low = textureSize(LOW_GRID, 0);
#ifdef UPSAMPLE_LIST
  vec3 n = texelFetch(point_normal, px, 0).xyz;
#  ifdef UPSAMPLE_TERMS
  ivec2 centre_px = ivec2(pixel.xy + 0.5);
  bool own = !same_surface(position, n, texelFetch(point_view, px, 0).w, centre_px);
#    ifndef UPSAMPLE_FIELD
  if (!own) {  /* the centre's surface: its terms */
    imageStore(out_diffuse, px, texelFetch(full_diffuse, centre_px, 0));
    imageStore(out_glossy, px, texelFetch(full_glossy, centre_px, 0));
    imageStore(out_world, px, texelFetch(full_world, centre_px, 0));
    return;
  }
#    endif
#  endif
  float u = (pixel.x + shift.x - float(stride / 2)) / float(stride);
  float v = (float(full.y - 1) - pixel.y + shift.y - float(stride / 2)) / float(stride);
#else
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  float u = float(px.x - stride / 2) / float(stride);
  float v = float(full.y - 1 - px.y - stride / 2) / float(stride);
#endif
  int i0 = clamp(int(floor(u)), 0, low.x - 1);
  int j0 = clamp(int(floor(v)), 0, low.y - 1);
  /* Quadratic B-spline weights over the 3 × 3 cells around the nearest one. */
  int ci = int(floor(u + 0.5));
  int cj = int(floor(v + 0.5));
  float tu = u - float(ci);
  float tv = v - float(cj);
  vec3 wu = vec3(0.5 * (0.5 - tu) * (0.5 - tu), 0.75 - tu * tu, 0.5 * (0.5 + tu) * (0.5 + tu));
  vec3 wv = vec3(0.5 * (0.5 - tv) * (0.5 - tv), 0.75 - tv * tv, 0.5 * (0.5 + tv) * (0.5 + tv));
  vec4 total = vec4(0.0);
  vec4 total2 = vec4(0.0);
#ifdef UPSAMPLE_TERMS
  vec4 total_diffuse = vec4(0.0);
  vec4 total_glossy = vec4(0.0);
  vec4 total_world = vec4(0.0);
#endif
  float weight = 0.0;
#ifdef UPSAMPLE_FIELD
  float turn2 = 0.0;       /* Σ weight × the emitters' turn² over the taps */
  float glossy_turn2 = 0.0; /* the same with the view's and the normal's turn */
  float eye_distance = max(length(position.xyz - eye.xyz), 1e-6);
#endif
  for (int dj = -1; dj <= 1; dj++) {
    for (int di = -1; di <= 1; di++) {
      float w = wu[di + 1] * wv[dj + 1];
      if (w <= 0.0) {
        continue;
      }
      int j = clamp(cj + dj, 0, low.y - 1);
      int i = clamp(ci + di, 0, low.x - 1);
      ivec2 q = traced_pixel(j, i, stride, full);
      vec4 pk = texelFetch(gbuffer_position, q, 0);
      vec3 nk = texelFetch(gbuffer_normal, q, 0).xyz;
      w *= pk.w > 0.5 ? 1.0 : 0.0;
      vec3 offset = pk.xyz - position.xyz;
      float facing = max(dot(n, nk), 0.0);
      float facing2 = facing * facing;
      float facing4 = facing2 * facing2;
      float plane = abs(dot(n, offset));
      float scale = 0.1 * length(offset) + 1e-4;
      w *= facing4 * facing4 * exp(-(plane / scale) * (plane / scale));
      ivec2 cell = ivec2(i, low.y - 1 - j);
#ifdef UPSAMPLE_IMAGE
      total += w * texelFetch(low_image, cell, 0);
#endif
#ifdef UPSAMPLE_TERMS
      total_diffuse += w * texelFetch(low_diffuse, cell, 0);
      total_glossy += w * texelFetch(low_glossy, cell, 0);
      total_world += w * texelFetch(low_world, cell, 0);
#endif
#ifdef UPSAMPLE_PAIR
      vec4 second = texelFetch(low_image2, cell, 0);
      total2 += w * second;
#endif
#ifdef UPSAMPLE_FIELD
      if (w > 0.0) {
        float step = length(offset);
        float room = second.w - step;
        float bend = length(n - nk);
        float turn = (room > 0.0 ? min(step / room, 1e15) : 1e15) + bend;
        turn2 += w * turn * turn;
        turn += eye.w * step / eye_distance + bend;
        glossy_turn2 += w * turn * turn;
      }
#endif
      weight += w;
    }
  }
  vec4 result = total / max(weight, 1e-30);
  vec4 result2 = total2 / max(weight, 1e-30);
#ifdef UPSAMPLE_TERMS
  if (own && weight > 1e-8) {  /* another surface, and gather points on it */
    imageStore(out_diffuse, px, total_diffuse / weight);
    imageStore(out_glossy, px, total_glossy / weight);
    imageStore(out_world, px, total_world / weight);
  }
  else {
    imageStore(out_diffuse, px, texelFetch(full_diffuse, centre_px, 0));
    imageStore(out_glossy, px, texelFetch(full_glossy, centre_px, 0));
    imageStore(out_world, px, texelFetch(full_world, centre_px, 0));
  }
#endif
#ifdef UPSAMPLE_FIELD
  if (weight <= 1e-8) {
    result = vec4(0.0, 0.0, 0.0, -1.0);
    result2 = vec4(0.0, 0.0, 0.0, -1.0);
  }
  else {  /* the turns' root mean square over the taps, by their weights */
    result.w = sqrt(glossy_turn2 / weight);
    result2.w = sqrt(turn2 / weight);
  }
#elif !defined(UPSAMPLE_TERMS)
  if (weight <= 1e-8) {
    float best = 1e30;
    result = vec4(0.0);
    result2 = vec4(0.0);
    for (int dj = -2; dj < 4; dj++) {
      for (int di = -2; di < 4; di++) {
        int j = clamp(j0 + dj, 0, low.y - 1);
        int i = clamp(i0 + di, 0, low.x - 1);
        float d = (float(dj) - 0.5) * (float(dj) - 0.5) + (float(di) - 0.5) * (float(di) - 0.5);
        if (texelFetch(gbuffer_position, traced_pixel(j, i, stride, full), 0).w > 0.5 && d < best) {
          result = texelFetch(low_image, ivec2(i, low.y - 1 - j), 0);
#ifdef UPSAMPLE_PAIR
          result2 = texelFetch(low_image2, ivec2(i, low.y - 1 - j), 0);
#endif
          best = d;
        }
      }
    }
  }
#endif
#ifdef UPSAMPLE_IMAGE
  imageStore(out_image, px, result);
#endif
#ifdef UPSAMPLE_PAIR
  imageStore(out_image2, px, result2);
#endif
}

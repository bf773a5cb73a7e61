/* G-buffer pass: what raycast.primary_visibility returns per pixel, bottom row first.
 * out_position: world xyz, 1 (hit); out_normal: shading normal turned to the camera (by the
 * face normal, as Cycles does), roughness; out_view: camera → point unit direction, material;
 * out_base: (Base Color sampled per texel, 1) where the material has a texture
 * (surface_slot = (slot, level-0 texels per metre × a pixel's footprint at unit distance)) at
 * scene/textures.primary_lod, else 0. A cut-out's fragment (surface_cutout = (alpha texture or
 * -1, alpha value); -2 opaque) is kept where textures.cutout_random of its point, view and
 * triangle is below its Alpha (level 0), as camera rays count hits in raycast. surface_params =
 * (parameter texture, first variant) of a material with Roughness / Metallic per texel: the
 * material written is its texel's variant (textures.SurfaceTextures.variant_at).
 * surface_normal_map = (normal map texture or -1, Strength), surface_tangent = the triangle's
 * textures.face_tangents row: the shading normal is perturbed as
 * textures.SurfaceTextures.normal_at. surface_glow = (emission texture or -1, Strength, its
 * texels per metre × a pixel's footprint at unit distance, 0), surface_base = the material's
 * Base Color value: out_base = (Base Color, the emission per texel × Strength packed by
 * pack_emission, textures.glsl: a float >= 2) where the material has an emission texture.
 * The Base Color is texture_taps² taps where the camera rays at the sub-pixel offsets
 * (tap_offsets.x … per axis: camera.filter_offsets) meet the fragment's plane (tap_point,
 * the twin of textures.tap_points), each at the level of a tap's share of the footprint, their
 * UVs extrapolated over the plane through the fragment's derivatives (exact: UV and position
 * are the same affine map of the plane): texture_taps = textures.primary_base's (taps, share)
 * (the centre pass: (4, 1); a sub-pixel pass, one of AA_SIDE² samples of its pixel: (1, 4),
 * its Base Color's and emission's footprint a quarter of the pixel's). The taps stand at
 * tap_offsets + tap_shift from the fragment's own camera ray: a view's sample, whose camera is
 * moved sub-pixel by o, gives −o, so its taps are its pixel's own square's (gbuffer.rasterize).
 * The texture code is there only with RASTER_TEXTURES (gbuffer.gbuffer_shader(textured)): a
 * scene without textures draws with the plain variant, 4-5x faster on llvmpipe, which runs the
 * code of a branch no fragment takes. */
#ifdef RASTER_TEXTURES
/* Where the camera ray at sub-pixel offset o (x right, y down, pixels) meets the plane through
 * p with normal n (textures.tap_points): p where the ray runs along the plane. */
vec3 tap_point(vec3 p, vec3 n, vec2 o)
{
  vec3 start, direction;
  if (camera_ortho > 0.5) {
    start = p + o.x * pixel_step_x + o.y * pixel_step_y;
    direction = camera_forward;
  }
  else {
    start = camera_position;
    vec3 rel = p - camera_position;
    float depth = dot(rel, camera_forward);
    direction = rel / (abs(depth) > 1e-12 ? depth : 1.0) + o.x * pixel_step_x +
                o.y * pixel_step_y;
  }
  float across = dot(direction, n);
  if (abs(across) <= 1e-9 * length(direction)) {
    return p;
  }
  return start + dot(p - start, n) / across * direction;
}
#endif

void main()
{
  /* the shading normal's change to the next pixel (before any discard: derivatives need the
   * whole quad), for the lobe's footprint (preview/lobe_footprint.py normal_spread) */
  vec3 unit_normal = dot(shading_normal, shading_normal) > 1e-24 ? normalize(shading_normal) :
                                                                   flat_normal;
  vec3 dnx = dFdx(unit_normal), dny = dFdy(unit_normal);
#ifdef RASTER_TEXTURES
  /* before any discard: derivatives need the whole quad */
  vec3 dpx = dFdx(world_position), dpy = dFdy(world_position);
  vec2 dux = dFdx(surface_uv), duy = dFdy(surface_uv);
#endif
  vec3 view = camera_ortho > 0.5 ? camera_forward : normalize(world_position - camera_position);
  if (surface_cutout.x > -1.5) {
    float alpha = surface_cutout.y;
#ifdef RASTER_TEXTURES
    if (surface_cutout.x > -0.5) {
      alpha = clamp(surface_alpha(int(surface_cutout.x + 0.5), surface_uv), 0.0, 1.0);
    }
#endif
    if (cutout_random(world_position, view, gl_PrimitiveID) >= alpha) {
      discard;
    }
  }
  if (surface.x < -1.5) { /* a holdout (gbuffer.rasterize): hides what is behind, shows nothing */
    out_normal = out_view = out_base = vec4(0.0);
    out_position = vec4(0.0, 0.0, 0.0, -1.0); /* w = -1: no surface, but the film's holdout */
    return;
  }
  float facing = dot(flat_normal, view) > 0.0 ? -1.0 : 1.0;
  vec3 n = shading_normal;
  n = dot(n, n) > 1e-24 ? normalize(n) : flat_normal;
#ifdef RASTER_TEXTURES
  if (surface_normal_map.x > -0.5) {
    /* a tangent-space normal map (textures.perturbed_normals, level 0) */
    vec3 t = surface_tangent.xyz - n * dot(surface_tangent.xyz, n);
    float tl = length(t);
    if (tl > 1e-12) {
      t /= tl;
      vec3 b = surface_tangent.w * cross(n, t);
      vec3 c = 2.0 * surface_texel(int(surface_normal_map.x + 0.5), surface_uv).rgb - 1.0;
      vec3 m = c.x * t + c.y * b + c.z * n;
      m /= max(length(m), 1e-12);
      m = n + (m - n) * max(surface_normal_map.y, 0.0);
      n = m / max(length(m), 1e-12);
    }
  }
#endif
  out_position = vec4(world_position, 1.0);
  out_normal = vec4(n * facing, surface.y);
  out_view = vec4(view, surface.x);
  out_base = vec4(0.0);
#ifdef RASTER_TEXTURES
  if (surface_params.x > -0.5) {
    /* Roughness / Metallic per texel: the material variant nearest the texel
     * (textures.variant_of; rint rounds half to even, as roundEven) */
    vec4 p = surface_texel(int(surface_params.x + 0.5), surface_uv);
    float r = roundEven(clamp(p.x, 0.0, 1.0) * float(ROUGHNESS_LEVELS - 1));
    float m = roundEven(clamp(p.y, 0.0, 1.0) * float(METALLIC_LEVELS - 1));
    out_view.w = surface_params.y + m * float(ROUGHNESS_LEVELS) + r;
    out_normal.w = r / float(ROUGHNESS_LEVELS - 1);
  }
  if (surface_slot.x > -0.5) {
    float distance = camera_ortho > 0.5 ? 1.0 : length(world_position - camera_position);
    float c = max(abs(dot(flat_normal, view)), FOOTPRINT_COS_MIN);
    float footprint = surface_slot.y * distance / sqrt(c);
    int taps = int(texture_taps.x + 0.5);
    footprint /= max(texture_taps.x, texture_taps.y);
    int slot = int(surface_slot.x + 0.5);
    if (taps <= 1) {
      float lod = log2(max(footprint, 1.0));
      out_base = vec4(clamp(surface_texture(slot, surface_uv, lod), 0.0, 1.0), 1.0);
    }
    else {
      float lod = log2(max(footprint, 1.0));
      float a11 = dot(dpx, dpx), a12 = dot(dpx, dpy), a22 = dot(dpy, dpy);
      float det = a11 * a22 - a12 * a12;
      bool solvable = abs(det) > 1e-30;
      vec3 sum = vec3(0.0);
      for (int i = 0; i < taps; i++) {
        for (int j = 0; j < taps; j++) {
          vec2 uv = surface_uv;
          if (solvable) {
            vec3 d = tap_point(world_position, flat_normal,
                               vec2(tap_offsets[i], tap_offsets[j]) + tap_shift) -
                     world_position;
            float r1 = dot(dpx, d), r2 = dot(dpy, d);
            uv += ((a22 * r1 - a12 * r2) * dux + (a11 * r2 - a12 * r1) * duy) / det;
          }
          sum += clamp(surface_texture(slot, uv, lod), 0.0, 1.0);
        }
      }
      out_base = vec4(sum / float(taps * taps), 1.0);
    }
  }
  if (surface_glow.x > -0.5) {
    if (surface_slot.x < -0.5) {
      out_base.rgb = surface_base;
    }
    float distance = camera_ortho > 0.5 ? 1.0 : length(world_position - camera_position);
    float c = max(abs(dot(flat_normal, view)), FOOTPRINT_COS_MIN);
    float lod = log2(max(surface_glow.z * distance / sqrt(c) / texture_taps.y, 1.0));
    vec3 glow = max(surface_texture(int(surface_glow.x + 0.5), surface_uv, lod), vec3(0.0));
    out_base.w = pack_emission(glow * surface_glow.y);
  }
#endif
  /* the lobe's roughness widened by the footprint (lobe_footprint.lobe_roughness):
   * α'² = α² + min(σ² (|∂n/∂x|² + |∂n/∂y|²), FOOTPRINT_LIMIT) */
  float a2 = clamp(out_normal.w, 0.0, 1.0);
  a2 *= a2;
  float widened = a2 * a2 + min(normal_footprint * (dot(dnx, dnx) + dot(dny, dny)),
                                FOOTPRINT_LIMIT);
  out_normal.w = sqrt(sqrt(widened));
}

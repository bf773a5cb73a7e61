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
 * The texture code is there only with RASTER_TEXTURES (gbuffer.gbuffer_shader(textured)): a
 * scene without textures draws with the plain variant, 4-5x faster on llvmpipe, which runs the
 * code of a branch no fragment takes. */
void main()
{
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
    float lod = log2(max(footprint, 1.0));
    out_base = vec4(clamp(surface_texture(int(surface_slot.x + 0.5), surface_uv, lod), 0.0,
                          1.0), 1.0);
  }
  if (surface_glow.x > -0.5) {
    if (surface_slot.x < -0.5) {
      out_base.rgb = surface_base;
    }
    float distance = camera_ortho > 0.5 ? 1.0 : length(world_position - camera_position);
    float c = max(abs(dot(flat_normal, view)), FOOTPRINT_COS_MIN);
    float lod = log2(max(surface_glow.z * distance / sqrt(c), 1.0));
    vec3 glow = max(surface_texture(int(surface_glow.x + 0.5), surface_uv, lod), vec3(0.0));
    out_base.w = pack_emission(glow * surface_glow.y);
  }
#endif
}

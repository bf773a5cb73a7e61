/* What a bounce ray of the gathers sees (voxgi_addon/gi/exact_indirect.py ray_radiance): the
 * radiance arriving back along the ray from `origin` in unit direction `d` — `world_rgb` on a
 * miss, else the hit's emission plus its exact direct light (one shadow ray per light and
 * stratum, `strata` = m of m × m, sample id `hit_id`, seed `seed` + 1) reflected toward the
 * origin by the Principled diffuse weight and, when `hit_glossy`, its glossy lobe (a metal's
 * integrated over an area lamp by LTC, glossy_ltc.glsl area_glossy; else toward the lamp's
 * lit part's middle). `th` = distance of the hit, BVH_FAR on a miss.
 * Samplers: bvh_* (bvh_common.glsl), lights and world_map (bvh_lights.glsl), materials ((M + 1) × 3 texels:
 * base colour, emission, (metallic, Specular IOR Level, roughness), (Base Color texture slot,
 * Roughness / Metallic texture slot, first variant)),
 * principled_lut, texture_table, texture_atlas (textures.glsl), radiance_cache (cache_lookup.glsl
 * cache_indirect). */

vec4 bvh_texel_normals(int k)
{
  return texelFetch(bvh_normals, ivec2(k & (BVH_WIDTH - 1), k >> BVH_WIDTH_LOG2), 0);
}

/* The surface UV at barycentrics `uv` of `triangle` (a SceneTriangles index): its corner UVs,
 * 2 texels per triangle index in texture_table's rows from the one its last texel of row 0
 * names (gpu_scene._update_textures). */
vec2 triangle_uv(int triangle, vec2 uv)
{
  int k = 2 * triangle;
  int row = int(texelFetch(texture_table, ivec2(BVH_WIDTH - 1, 0), 0).x + 0.5);
  vec4 c01 = texelFetch(texture_table, ivec2(k & (BVH_WIDTH - 1), row + (k >> BVH_WIDTH_LOG2)), 0);
  vec4 c2 = texelFetch(texture_table,
                       ivec2((k + 1) & (BVH_WIDTH - 1), row + ((k + 1) >> BVH_WIDTH_LOG2)), 0);
  return (1.0 - uv.x - uv.y) * c01.xy + uv.x * c01.zw + uv.y * c2.xy;
}

/* The emission where a ray hits `triangle` of `material` at barycentrics `uv`: per texel
 * (level 0, as the Base Color at bounce hits) where the material has an Emission Color texture
 * (materials row 4: (slot, Strength); textures.SurfaceTextures.emission_at), else its value
 * (row 1) — exact_indirect.hit_emission. */
vec3 hit_emission(int material, int triangle, vec2 uv)
{
#ifdef BVH_TEXTURES
  vec4 glow = texelFetch(materials, ivec2(material, 4), 0);
  if (glow.x >= -0.5) {
    return max(surface_texture(int(glow.x + 0.5), triangle_uv(triangle, uv), 0.0), vec3(0.0)) *
           glow.y;
  }
#endif
  return texelFetch(materials, ivec2(material, 1), 0).rgb;
}

/* The share of lamp picks light `light` takes at p with normal n (exact_indirect.lamp_picks):
 * its Diffuse Direct there as if nothing hid it and an area lamp were a point at its centre
 * (luminance), 0 for a padding row. A bounce hit traces the shadow rays of one lamp picked by
 * these, its light divided by its chance (ray_paths). */
float lamp_pick_weight(int light, vec3 p, vec3 n)
{
  vec4 head = light_texel(light, 0);
  int kind = int(head.x);
  if (kind < 0) {
    return 0.0;
  }
  vec4 colour = light_texel(light, 1);
  float power = colour.w * dot(colour.rgb, LUMA);
  if (kind == 0) {
    return power * max(dot(n, -light_texel(light, 5).xyz), 0.0) / M_PI_F;
  }
  vec4 centre = light_texel(light, 2);
  vec3 delta = centre.xyz - p;
  float d2 = dot(delta, delta);
  float c = max(dot(n, delta), 0.0) / sqrt(max(d2, 1e-30));
  if (kind == 3) { /* Lambert's small-source form, the lamp's area keeping it finite */
    float area = light_texel(light, 6).x;
    float facing = max(dot(light_texel(light, 5).xyz, -delta), 0.0) / sqrt(max(d2, 1e-30));
    return power * c * facing / (M_PI_F * M_PI_F * (d2 + area));
  }
  float cone = 1.0;
  if (kind == 2) { /* a spot's cone, as point_light's */
    vec4 emit = light_texel(light, 5);
    float cos_half = light_texel(light, 4).w;
    float cos_phi = dot(-delta, emit.xyz) / sqrt(max(d2, 1e-30));
    float x = emit.w <= 0.0 ? (cos_phi > cos_half ? 1.0 : 0.0) :
                              clamp((cos_phi - cos_half) / ((1.0 - cos_half) * emit.w), 0.0, 1.0);
    cone = emit.w <= 0.0 ? x : x * x * (3.0 - 2.0 * x);
  }
  return power * cone * c / (4.0 * M_PI_F * M_PI_F * (d2 + centre.w * centre.w));
}

/* lamp_pick_weight at a hit: at a metal hit whose glossy lobe is taken (`metal`), times what
 * the hit sends toward v (its diffuse weight `diffuse` and its lobe toward the lamp, as the
 * lamps' loop in ray_paths reflects them), since a metal's light is its lobe's
 * (exact_indirect.lamp_picks' weights). */
float hit_lamp_weight(int light, vec3 p, vec3 n, bool metal, vec3 diffuse, vec3 v, vec3 base,
                      vec3 params)
{
  float w = lamp_pick_weight(light, p, n);
#ifdef BVH_NO_METALS
  return w; /* no metal in the scene: the code is left out (llvmpipe pays for it untaken) */
#else
  if (!metal || w <= 0.0) {
    return w;
  }
  vec3 towards = light_aim(light, p, n);
  float c = dot(n, towards);
  float lobe = c > 1e-4 ? (M_PI_F / c) *
                              dot(principled_glossy_reflectance(base, params.x, params.y,
                                                                params.z, n, v, towards),
                                  LUMA) :
                          0.0;
  return w * (dot(diffuse, LUMA) + lobe);
#endif
}

/* The chance of picking a lamp of pick weight w among `count` lamps whose weights sum to
 * `total`: a share LAMP_PICK_FLOOR spread evenly (no lamp that may light p is never picked,
 * whatever the weights leave out), the rest by weight. */
float lamp_chance(float w, float total, int count)
{
  return total > 0.0 ? (1.0 - LAMP_PICK_FLOOR) * w / total + LAMP_PICK_FLOOR / float(count) :
                       1.0 / float(count);
}

/* ray_radiance without the radiance cache (voxgi_addon/gi/exact_indirect.py ray_paths): also
 * the hit `x`, its shading normal `ns` (turned toward the origin) and `cache_weight`, what the
 * hit reflects toward the origin of light arriving uniformly (the diffuse weight + the glossy
 * lobes' albedo); 0 on a miss. What the ray returns with a cache is linear in it, so the cache
 * traces its rays once (cache_paths.glsl) and iterates by lookups (cache_relax.glsl). */
/* The last ray_paths hit's roughness and metallic (its material's, per texel where a texture
 * sets them): ray_radiance samples a metal's lobe from them. */
float hit_roughness = 1.0;
float hit_metallic = 0.0;

vec3 ray_paths(vec3 origin, vec3 d, uint hit_id, uint seed, int strata, bool hit_glossy,
               vec3 world_rgb, bool emission_seen, out float th, out vec3 x, out vec3 ns,
               out vec3 cache_weight, out vec3 glossy_weight)
{
  int triangle, slot;
  vec2 uv;
  x = ns = cache_weight = glossy_weight = vec3(0.0);
  if (!bvh_closest_hit(origin, d, 0.0, BVH_FAR, th, triangle, slot, uv)) {
    th = BVH_FAR;
    return world_rgb;
  }
  int last_material = textureSize(materials, 0).x - 1;
  x = origin + th * d;
  vec3 face = bvh_triangle_face_normal(slot);
  vec3 smooth_n = (1.0 - uv.x - uv.y) * bvh_texel_normals(3 * slot).xyz +
                  uv.x * bvh_texel_normals(3 * slot + 1).xyz +
                  uv.y * bvh_texel_normals(3 * slot + 2).xyz;
  float len = length(smooth_n);
  ns = len > 1e-12 ? smooth_n / len : face;
  ns *= dot(face, d) > 0.0 ? -1.0 : 1.0;
  int material = bvh_triangle_material(slot);
  material = (material >= 0 && material < last_material) ? material : last_material;
  vec3 glow = hit_emission(material, triangle, uv);
  /* Roughness / Metallic per texel (textures.SurfaceTextures.variant_at, level 0): row 3's
   * (.y, .z) = (parameter texture, first variant), -1 none. Without BVH_TEXTURES (no material
   * of the scene samples a texture: gpu_bvh.bvh_shader) the texture code is left out, since
   * llvmpipe pays for a branch's code at every hit whether a lane takes it or not. */
#ifdef BVH_TEXTURES
  vec4 variant = texelFetch(materials, ivec2(material, 3), 0);
  if (variant.y > -0.5) {
    vec4 p = surface_texel(int(variant.y + 0.5), triangle_uv(triangle, uv));
    float r = roundEven(clamp(p.x, 0.0, 1.0) * float(ROUGHNESS_LEVELS - 1));
    float m = roundEven(clamp(p.y, 0.0, 1.0) * float(METALLIC_LEVELS - 1));
    material = int(variant.z + 0.5) + int(m) * ROUGHNESS_LEVELS + int(r);
  }
  vec3 base = texelFetch(materials, ivec2(material, 0), 0).rgb;
  vec3 emission = glow;
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
  /* Base Color per texel (textures.glsl; level 0, as exact_indirect.ray_radiance) */
  int texture_slot = int(texelFetch(materials, ivec2(material, 3), 0).x);
  if (texture_slot >= 0) {
    base = clamp(surface_texture(texture_slot, triangle_uv(triangle, uv), 0.0), 0.0, 1.0);
  }
#else
  vec3 base = texelFetch(materials, ivec2(material, 0), 0).rgb;
  vec3 emission = glow;
  vec3 params = texelFetch(materials, ivec2(material, 2), 0).rgb;
#endif
  /* The Principled diffuse weight seen from the receiver (docs/gi_pipeline.md "The Accurate
   * integrator"). */
  vec3 weight = principled_diffuse_weight(base, params.x, params.y, params.z,
                                          clamp(-dot(ns, d), 0.0, 1.0));
  vec3 lit_at = x + ns * surface_offset(x, SURFACE_EPSILON);
  /* uniform light (the radiance cache's) is also reflected by the glossy lobes' albedo */
  glossy_weight = principled_glossy_color(base, params.x, params.y, params.z,
                                          clamp(-dot(ns, d), 0.0, 1.0));
  /* with the emitters among the lights their light comes by next-event estimation: a ray
   * landing on one adds no emission (exact_indirect.ray_radiance) unless `emission_seen` */
  vec3 radiance = (emission_seen || emitter_header().w < 0.5) ? emission : vec3(0.0);
  /* One lamp's shadow rays, picked by hit_lamp_weight, its light over its chance
   * (exact_indirect.lamp_picks): a hit's cost no longer grows with the lamps. */
  int lamp_count = textureSize(lights, 0).y;
  int picked = 0;
  float chance = 1.0;
  bool pick = lamp_count > 1;
  bool metal = hit_glossy && params.x >= METAL_FOLLOWED;
  if (pick) {
    float total = 0.0;
    int real = 0;
    for (int light = 0; light < lamp_count; light++) {
      total += hit_lamp_weight(light, lit_at, ns, metal, weight, -d, base, params);
      real += int(light_texel(light, 0).x) >= 0 ? 1 : 0;
    }
    float u = unit_float(point_stream(hit_id, LAMP_PICK_STREAM, seed + 1u));
    float below = 0.0;
    picked = -1;
    for (int light = 0; light < lamp_count; light++) {
      float w = hit_lamp_weight(light, lit_at, ns, metal, weight, -d, base, params);
      float p = int(light_texel(light, 0).x) >= 0 ? lamp_chance(w, total, max(real, 1)) : 0.0;
      if (picked < 0 && p > 0.0 && (u < below + p || light == lamp_count - 1)) {
        picked = light;
        chance = p;
      }
      below += p;
    }
    picked = max(picked, 0);
  }
  vec3 lamps = vec3(0.0);
  for (int light = picked; light < (pick ? picked + 1 : lamp_count); light++) {
    vec3 direct = light_direct(light, lit_at, ns, hit_id, seed + 1u, strata);
    lamps += weight * direct;
#if !defined(BVH_NO_AREA) && !defined(BVH_NO_METAL_AREA)
    vec4 head = light_texel(light, 0);
    if (hit_glossy && params.x >= METAL_FOLLOWED && int(head.x) == 3) {
      /* a metal under an area lamp: the lobe over it (LTC, glossy_ltc.glsl) by the visible
       * share of its light (exact_indirect._area_shine); the code only in a scene with a metal
       * (gpu_bvh.absent_lights) */
      vec3 aim;
      float unshadowed = polygon_irradiance(light, int(head.z), lit_at, ns, aim) *
                         light_texel(light, 6).y * dot(light_texel(light, 1).rgb, LUMA);
      float lit = dot(direct, LUMA);
      if (unshadowed > 0.0 && lit > 0.0) {
        lamps += clamp(lit / unshadowed, 0.0, 1.0) *
                 area_glossy(light, int(head.z), lit_at, ns, -d, base, params);
      }
      continue;
    }
#endif
    vec3 towards = light_aim(light, lit_at, ns);
    float c = dot(ns, towards);
    if (hit_glossy && c > 1e-4 && dot(direct, vec3(1.0)) > 0.0) {
      lamps += direct * (3.14159265358979323846 / c) *
               principled_glossy_reflectance(base, params.x, params.y, params.z, ns, -d,
                                             towards);
    }
  }
  radiance += lamps / chance;
  /* the world and the emitters light the hit too: its diffuse weight and, when `hit_glossy`,
   * its glossy lobe from the same shadow rays (exact_indirect.ray_radiance); the world's
   * strata one ray each (world_light.one_technique) */
  vec3 world_glossy, emitter_glossy;
  radiance += weight * (world_light_lobe(lit_at, ns, hit_id, seed + 1u, strata, hit_glossy, -d,
                                         base, params, true, world_glossy) +
                        emitters_light_lobe(lit_at, ns, hit_id, seed + 1u, strata, false,
                                            vec4(0.0), hit_glossy, -d, base, params,
                                            emitter_glossy));
  hit_roughness = clamp(params.z, 0.0, 1.0);
  hit_metallic = params.x;
  cache_weight = weight + glossy_weight;
  return radiance + world_glossy + emitter_glossy;
}

/* The chance that Cycles picked the receiver's glossy closure for the ray being traced (0 for
 * the diffuse gather): Cycles counts a bounce by the closure it picked but files the light by
 * the closures' values, so a glossy-gather ray was mostly picked diffuse and leaves one diffuse
 * bounce fewer to the hit (exact_glossy._Lobe.glossy_chance). Set per ray by bvh_glossy.glsl. */
float receiver_glossy = 0.0;
/* Density of the visible-normal sample l (voxgi_addon/gi/exact_glossy.py _Lobe.pdf; the glossy
 * gather's rays and receiver_glossy's chance): D of
 * normalize(v + l) computed as principled_glossy_reflectance does (1 − cos² as |n × h|², exact
 * in float32 near a mirror's peak), so that it cancels in the weight. */
float lobe_pdf(vec3 n, vec3 v, vec3 l, float alpha2, float pdf_scale)
{
  vec3 h_eval = normalize(v + l);
  float cos_nh = dot(n, h_eval);
  vec3 nxh = cross(n, h_eval);
  float den = min(dot(nxh, nxh), 1.0) + alpha2 * min(cos_nh * cos_nh, 1.0);
  return alpha2 / (M_PI_F * max(den * den, 1e-30)) / pdf_scale;
}

/* The receiver's Principled inputs from its material code (gather_point's ray.w; the tables'
 * last column for none): base colour and (metallic, Specular IOR Level, roughness). */
void receiver_material(float code, out vec3 base, out vec3 params)
{
  int last_material = textureSize(materials, 0).x - 1;
  int material = int(code + 0.5);
  material = (material >= 0 && material < last_material) ? material : last_material;
  base = texelFetch(materials, ivec2(material, 0), 0).rgb;
  params = texelFetch(materials, ivec2(material, 2), 0).rgb;
}

/* glossy_pick_chance's picks for a receiver seen at cos_ni: (its glossy and its diffuse
 * directional albedo (luminance), the latter / π, the lobe's alpha², lobe_pdf's scale). */
vec4 closure_picks(vec3 base, vec3 params, float cos_ni)
{
  float rough = clamp(params.z, 0.0, 1.0);
  float alpha2 = rough * rough * rough * rough;
  float mu = clamp(cos_ni, 0.0, 1.0);
  float c = max(cos_ni, 1e-4);
  return vec4(dot(principled_glossy_color(base, params.x, params.y, rough, mu), LUMA),
              dot(principled_diffuse_weight(base, params.x, params.y, rough, mu), LUMA) /
                  M_PI_F,
              alpha2, 4.0 * c * (1.0 + pr_ggx_lambda(alpha2, c)));
}

/* receiver_glossy of a diffuse-gather ray l at a receiver of normal n seen along v
 * (exact_glossy.glossy_pick_chance): its glossy closure's sample weight × the lobe's density
 * over both closures' (picks = (glossy weight, diffuse weight / π, alpha², pdf_scale); 0 on a
 * mirror, whose reflection a diffuse direction never is). */
float glossy_pick_chance(vec3 n, vec3 v, vec3 l, vec4 picks)
{
  float pg = picks.x * lobe_pdf(n, v, l, picks.z, picks.w);
  float pd = picks.y * max(dot(l, n), 0.0);
  return pg / max(pg + pd, 1e-30);
}

/* The diffuse gather's rays follow their near hits one bounce further (ray_radiance; set by
 * bvh_gather.glsl): exact_indirect.ray_radiance(near_field=the receivers' normals). */
bool near_follow = false;
/* The receiver's normal (the gather point's, then each followed hit's): only a hit that faces
 * it is near (NEAR_FACING; exact_indirect._near). */
vec3 near_normal = vec3(0.0);

/* The cosine-distributed direction about ns a near hit is followed along (exact_indirect
 * near_bounce_rays): the concentric disc point of the hash of the ray's light-sample id and
 * seed (CONTINUE_STREAM, as a metal's reflection: a hit takes one or the other), lifted. */
vec3 near_bounce_ray(vec3 ns, uint hit_id, uint seed)
{
  vec3 t, b;
  perpendicular_basis(ns, t, b);
  uint h = point_stream(hit_id, CONTINUE_STREAM, seed);
  vec2 disk = concentric_disk(vec2(unit_float(h), unit_float(pcg_hash(h))));
  return normalize(disk.x * t + disk.y * b + sqrt(max(0.0, 1.0 - dot(disk, disk))) * ns);
}

/* The metal hits' lobe (exact_indirect.metal_lobe_rays): a GGX visible normal of roughness
 * hit_roughness about ns seen from -d, from the hash of the ray's light-sample id and seed
 * (CONTINUE_STREAM); returns the reflected direction (below the surface: no light). */
vec3 metal_lobe_ray(vec3 ns, vec3 d, uint hit_id, uint seed)
{
  float alpha = max(hit_roughness * hit_roughness, 1e-3);
  vec3 t, b;
  perpendicular_basis(ns, t, b);
  vec3 v = -d;
  vec3 v_local = normalize(vec3(dot(t, v), dot(b, v), max(dot(ns, v), 1e-4)));
  uint h = point_stream(hit_id, CONTINUE_STREAM, seed);
  vec3 hl = vndf_half_vector(v_local, alpha, vec2(unit_float(h), unit_float(pcg_hash(h))));
  return reflect(d, hl.x * t + hl.y * b + hl.z * ns);
}

/* The metal hit x's reflection followed one bounce further (exact_indirect.follow_metal_hits):
 * its origin `o` and direction `dir`; false when it points below the surface (no light). The
 * second hit's light samples are drawn with id pcg_hash(hit_id ^ CONTINUE_STREAM). */
bool metal_follow(vec3 x, vec3 ns, vec3 d, uint hit_id, uint seed, out vec3 o, out vec3 dir)
{
  dir = metal_lobe_ray(ns, d, hit_id, seed);
  o = x + surface_offset(x, SURFACE_EPSILON) * ns;
  return dot(dir, ns) > 0.0;
}

/* One path of ray_radiance, a bounce at a time (path_start, path_step): the diffuse gather runs
 * its rays' paths as one stream, each step one bounce of whichever path a lane is on, so a
 * lane whose path is followed further does not hold the others (llvmpipe runs a work group's
 * lanes in lockstep: a loop of bounces inside a loop of rays ran as many bounces as the lane
 * that followed most, for every ray). */
struct Path {
  vec3 total;   /* the light gathered so far */
  vec3 carried; /* the throughput of the bounce to trace */
  vec3 o;       /* its origin and direction */
  vec3 dir;
  float th;     /* the first hit's distance, BVH_FAR on a miss */
  uint id_now;  /* the light-sample id of the hit being shaded */
  int bounce;
  int follows;  /* near hits followed so far (exact_indirect._follow_near) */
  bool metal;   /* a metal's reflection followed: its hit reads the cache whole */
};

Path path_start(vec3 origin, vec3 d, uint hit_id)
{
  Path path;
  path.total = vec3(0.0);
  path.carried = vec3(1.0);
  path.o = origin;
  path.dir = d;
  path.th = BVH_FAR;
  path.id_now = hit_id;
  path.bounce = 0;
  path.follows = 0;
  path.metal = false;
  return path;
}

/* One bounce of `path` (ray_radiance's, below): the hit's light, then the cache's at it or
 * a bounce further; true when the path is whole (at most MAX_FOLLOWS + 1 bounces). */
bool path_step(inout Path path, uint seed, int strata, bool hit_glossy, vec3 world_rgb,
               bool emission_seen)
{
  bool cached = textureSize(radiance_cache, 0).x > 1;
  /* one bounce with Cycles' glossy bounces going on: no iteration of the cache's own, its
   * first one ahead (part 1), which only a glossy scatter carries (exact_indirect
   * RayPaths.with_cache; docs/gi_pipeline.md "One bounce and Cycles' glossy bounces") */
  bool ahead_only = cached && cache_iterations() == 0;
  bool first = path.bounce == 0;
  path.bounce++;
  float t_hit;
  vec3 x, ns, cache_weight, glossy_weight;
  path.total += path.carried * ray_paths(path.o, path.dir, path.id_now, seed, first ? strata : 1,
                                         first ? hit_glossy : true,
                                         first ? world_rgb : vec3(0.0),
                                         first && emission_seen, t_hit, x, ns, cache_weight,
                                         glossy_weight);
  if (first) {
    path.th = t_hit;
  }
  if (t_hit >= BVH_FAR || (path.follows > 0 && path.follows >= cache_iterations())) {
    return true; /* left the scene, or the followed path holds every bounce */
  }
  /* f followed bounces on, the cache f iterations fewer: part 0, else part f + 1 */
  int follows = path.follows;
  vec4 arriving = cache_indirect(x, ns, ahead_only ? 1 : (follows == 0 ? 0 : follows + 1));
  if (cached && near_follow && hit_metallic < METAL_FOLLOWED && follows < MAX_FOLLOWS &&
      !path.metal && follows < cache_iterations() && cache_has_levels() &&
      dot(ns, near_normal) < NEAR_FACING && t_hit < NEAR_FIELD * cache_cell_size(x)) {
    /* the near field: a hit facing the receiver, or meeting it at a crease, within
     * NEAR_FIELD of the cache's cells lies where the cache's voxels cannot hold its light,
     * so one diffuse bounce is followed exactly, again where it lands near
     * (docs/gi_pipeline.md "The near field followed", "Creases followed too") */
    path.total += path.carried * glossy_weight * arriving.a * arriving.rgb;
    path.carried *= cache_weight;
    path.follows++;
    near_normal = ns;
    path.o = x + surface_offset(x, SURFACE_EPSILON) * ns;
    path.dir = near_bounce_ray(ns, path.id_now, seed);
    path.id_now = pcg_hash(path.id_now ^ CONTINUE_STREAM);
    return path.bounce > MAX_FOLLOWS;
  }
  /* the hit's glossy lobe followed one reflection further (exact_indirect
   * lobe_follow_chance): a metal's always, a dielectric's by its glossy share q, carrying
   * the lobe's light / q; not followed, the lobe's light is left to the followed ones */
  float q = clamp(dot(glossy_weight, LUMA) / max(dot(cache_weight, LUMA), 1e-30), 0.0, 1.0);
  q = hit_metallic >= METAL_FOLLOWED ? 1.0 : q;
  bool lobe = first && cached && !ahead_only;
  bool lobe_followed = lobe && q > 0.0 &&
                       (q >= 1.0 || unit_float(pcg_hash(path.id_now ^ LOBE_FOLLOW_STREAM)) < q);
  if (lobe && !lobe_followed) {
    cache_weight -= glossy_weight;
    glossy_weight = vec3(0.0);
  }
  if (lobe_followed) {
    path.total += (cache_weight - glossy_weight) * (1.0 + max(receiver_glossy, 0.0) * arriving.a) *
                  arriving.rgb;
    path.carried = glossy_weight / q;
    if (!metal_follow(x, ns, path.dir, path.id_now, seed, path.o, path.dir)) {
      return true;
    }
    path.id_now = pcg_hash(path.id_now ^ CONTINUE_STREAM);
    path.metal = true;
    return path.bounce > MAX_FOLLOWS;
  }
  /* the diffuse share: one diffuse bounce more where the receiver's path was picked glossy
   * (receiver_glossy); the glossy lobes: always (radiance_cache.one_more_bounce) */
  float receiver = first ? max(receiver_glossy, 0.0) : 0.0;
  path.total += path.carried * (ahead_only ?
                                (cache_weight - glossy_weight) * receiver + glossy_weight :
                                receiver > 0.0 ?
                                (cache_weight - glossy_weight) * (1.0 + receiver * arriving.a) +
                                    glossy_weight * (1.0 + arriving.a) :
                                cache_weight + glossy_weight * arriving.a) * arriving.rgb;
  return true;
}

vec3 ray_radiance(vec3 origin, vec3 d, uint hit_id, uint seed, int strata, bool hit_glossy,
                  vec3 world_rgb, bool emission_seen, out float th)
{
  /* The hit's own light (ray_paths), then the radiance cache's indirect light at it: bounces
   * 2 … N (cache_indirect). A glossy lobe does not take the cache's light as uniform: it is
   * followed one reflection further (metal_lobe_ray; a dielectric's by its glossy share),
   * whose hit adds its own light and its cache's, carried by the Glossy Color
   * (docs/gi_pipeline.md "Metals reflect where they point", "Where the box's regional bias
   * comes from"). In the diffuse gather (near_follow) a hit within NEAR_FIELD cache cells
   * that faces its receiver (NEAR_FACING) is followed a diffuse bounce further instead,
   * MAX_FOLLOWS times at most, each landing reading the cache an iteration fewer ("The near
   * field followed"). One loop for all, so
   * the later hits' code is not compiled again and costs nothing where no lane follows. */
  Path path = path_start(origin, d, hit_id);
  for (int bounce = 0; bounce <= MAX_FOLLOWS; bounce++) {
    if (path_step(path, seed, strata, hit_glossy, world_rgb, emission_seen)) {
      break;
    }
  }
  th = path.th;
  return path.total;
}

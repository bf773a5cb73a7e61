/* Diffuse Direct per G-buffer pixel with shadow rays through the BVH (bvh_lights.glsl): what
 * preview.direct_light computes with shadows "RAYS" — diffuse_direct at the point lifted by
 * SURFACE_EPSILON along its normal, sample id = pixel index (row 0 on top).
 * Push constants: sampling = (seed, strata side m of this dispatch, mode, emitter_field
 * given); strata = (M, row, column, 0): the dispatch draws the m × m block at (row, column)
 * of each light's M × M strata (sampling.glsl STRATA_BLOCK; the whole set when m = M), so the
 * anti-aliased preview's sub-pixel passes share one stratified set of shadow rays.
 * out = (rgb, the variance of the world's part's luminance: bvh_lights.glsl world_variance).
 * gbuffer_view = (ray direction, material). sampling.z, the mode:
 * 0: Diffuse Direct, the emitters' exact unshadowed sum evaluated at every texel
 * (O(emissive triangles), bvh_lights.glsl emitters_unshadowed);
 * 1, the same in a pass of the anti-aliased preview: centre_position, centre_normal,
 * centre_view hold the pixel centres' G-buffer at the same texels and centre_unshadowed
 * mode 2's sums there (from the emitters' field, docs/gi_pipeline.md "Where a preview's time
 * goes"); a texel whose pass sees the surface its centre sees (same_surface.glsl) takes the
 * centre's sum, the others emitter_field's at their own point (sampling.w = 1;
 * upsample.glsl UPSAMPLE_LIST: (sum, the angle the emitters turn across its taps, < 0 where
 * none fits)) where its angle is within NEAR_STEP, and evaluate it elsewhere (the shadow
 * rays are the pass's own);
 * 2: out = (the emitters' exact unshadowed sum alone, emitters_unshadowed, the distance to
 * the nearest emissive triangle that can light the point, bvh_lights.glsl
 * emitters_distance), no rays: the field at the gather points; with emitter_field given
 * (sampling.w = 1), (the field's sum where it holds, else the exact one, 0): the pixel
 * centres' sums, which mode 1 reads as its centre_unshadowed.
 * shown.x = 1 (modes 0 and 1): diffuse_colour holds the Diffuse Color at the same texels, and
 * a texel where it is 0 (a full metal, a black surface: its light is only read times it)
 * traces nothing and stores 0. */

/* The triangle under the pixel's point `q` seen along unit `view` with shading normal `n`
 * (a camera ray from TERMINATOR_REACH back to as far past it: surface_lookup.find_triangles,
 * terminator.find_lifts), and its
 * lift (terminator.lift) for the lights' shadow rays (bvh_lights.glsl shadow_hit). */
void terminator_set(vec3 q, vec3 view, vec3 n)
{
  int slot;
  vec2 uv;
  vec3 ng; /* the geometric normal on the shaded side */
  if (!surface_triangle(q, view, n, slot, uv, ng)) {
    return;
  }
  vec3 V0 = bvh_texel_triangles(3 * slot).xyz;
  vec3 V1 = V0 + bvh_texel_triangles(3 * slot + 1).xyz;
  vec3 V2 = V0 + bvh_texel_triangles(3 * slot + 2).xyz;
  ivec2 at0 = ivec2((3 * slot) & (BVH_WIDTH - 1), (3 * slot) >> BVH_WIDTH_LOG2);
  ivec2 at1 = ivec2((3 * slot + 1) & (BVH_WIDTH - 1), (3 * slot + 1) >> BVH_WIDTH_LOG2);
  ivec2 at2 = ivec2((3 * slot + 2) & (BVH_WIDTH - 1), (3 * slot + 2) >> BVH_WIDTH_LOG2);
  vec3 N0 = texelFetch(bvh_normals, at0, 0).xyz;
  vec3 N1 = texelFetch(bvh_normals, at1, 0).xyz;
  vec3 N2 = texelFetch(bvh_normals, at2, 0).xyz;
  float b0 = 1.0 - uv.x - uv.y, b1 = uv.x, b2 = uv.y;
  vec3 p = V0 * b0 + V1 * b1 + V2 * b2;
  vec3 ni = N0 * b0 + N1 * b1 + N2 * b2;
  float a = dot(N2 - N0, V0 - V2);
  float b = dot(N2 - N1, V1 - V2);
  float c = dot(N1 - N0, V1 - V0);
  float h = a * b0 * (b0 - 1.0) + (a + b + c) * b0 * b1 + b * b1 * (b1 - 1.0);
  if (dot(ni, ng) > 0.0) {
    float e0 = max(max(dot(V1 - V0, N0), dot(V2 - V0, N0)), 0.0);
    float e1 = max(max(dot(V0 - V1, N1), dot(V2 - V1, N1)), 0.0);
    float e2 = max(max(dot(V0 - V2, N2), dot(V1 - V2, N2)), 0.0);
    float up = min(min(max(dot(V0 - p, N0) + e0, 0.0), max(dot(V1 - p, N1) + e1, 0.0)),
                   max(dot(V2 - p, N2) + e2, 0.0));
    h = max(up, 0.5 * h);
  }
  else {
    float f0 = max(max(dot(V0 - V1, N0), dot(V0 - V2, N0)), 0.0);
    float f1 = max(max(dot(V1 - V0, N1), dot(V1 - V2, N1)), 0.0);
    float f2 = max(max(dot(V2 - V0, N2), dot(V2 - V1, N2)), 0.0);
    float down = min(min(max(dot(p - V0, N0) + f0, 0.0), max(dot(p - V1, N1) + f1, 0.0)),
                     max(dot(p - V2, N2) + f2, 0.0));
    h = min(-down, 0.5 * h);
  }
  terminator_lift = ni * h;
  terminator_ng = ng;
  terminator_n = n;
}

void main()
{
  ivec2 px = ivec2(gl_GlobalInvocationID.xy);
  ivec2 size = imageSize(out_image);
  if (px.x >= size.x || px.y >= size.y) {
    return;
  }
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  vec3 p = position.xyz + n * surface_offset(position.xyz, SURFACE_EPSILON);
  int mode = int(sampling.z + 0.5);
  if (mode == 2 && sampling.w > 0.5) {  /* the field where it holds, else the sum, w = 0 */
    vec4 field = texelFetch(emitter_field, px, 0);
    bool held = field.w >= 0.0 && field.w <= NEAR_STEP;
    imageStore(out_image, px, vec4(held ? field.rgb : emitters_unshadowed(p, n, true), 0.0));
    return;
  }
  if (mode == 2) {
    imageStore(out_image, px, vec4(emitters_unshadowed(p, n, true),
                                   emitters_distance(p, n)));
    return;
  }
  if (shown.x > 0.5 && texelFetch(diffuse_colour, px, 0).rgb == vec3(0.0)) {
    /* no Diffuse Color: the light is read times it alone (aa_light.glsl), nothing to trace */
    imageStore(out_image, px, vec4(0.0));
    return;
  }
  vec4 known = vec4(0.0); /* w = 0: evaluated here */
  if (mode == 1) {
    vec4 field = sampling.w > 0.5 ? texelFetch(emitter_field, px, 0) : vec4(-1.0);
    if (same_surface(position, n, texelFetch(gbuffer_view, px, 0).w, px)) {
      known = vec4(texelFetch(centre_unshadowed, px, 0).rgb, 1.0);
    }
    else if (field.w >= 0.0 && field.w <= NEAR_STEP) {
      known = vec4(field.rgb, 1.0);
    }
  }
  uint id = position.w > 1.5 ? uint(position.w) - 2u  /* a listed pixel: aa_compact.glsl */
                             : uint((size.y - 1 - px.y) * size.x + px.x);
  terminator_set(position.xyz, texelFetch(gbuffer_view, px, 0).xyz, n);
  vec3 value = diffuse_direct(p, n, id, uint(sampling.x), int(sampling.y), known);
  imageStore(out_image, px, vec4(value, world_variance));
}

/* One pass of the edge-aware à-trous filter (voxgi_addon/preview/denoise.py atrous_filter,
 * ported line for line) over the reduced-resolution gather. low_image = (light rgb, AO),
 * low_variance = (var of the light's luminance mean, var of the AO mean); taps 2^i cells apart,
 * B3-spline weights × same-surface terms (normal^32, plane) × per signal
 * exp(−|Δ| / (SIGMA_LUMINANCE·√(var_p + var_q) + 1e-6)) (the light's weight × the AO's
 * term widened by AO_TOLERANCE too), var_p the centre's variance prefiltered over 3 × 3
 * valid cells, var_q the tap's own (why both: denoise.py).
 * The value is a weighted local linear fit through the taps (denoise.py _fit): the weighted
 * mean where the taps surround the cell, corrected by the slope where they lie on one side.
 * Variances are filtered with squared weights (the fit's own weights). A cell whose prefiltered standard error is
 * within settle.x of its value is settled: kept as it is (denoise.py NOISE_TARGET; 0 for a
 * pixel's world light, passes.py WORLD_NOISE_TARGET: only a cell with no variance is).
 * grid = (stride, full width, full height, tap step); low-resolution rows count from the bottom;
 * options.x = 1: the local linear fit, 0: the weighted mean; options.y: the kernel stretched over
 * that many times its width (2 in the first pass over a grid with holes: denoise.py HOLE_SPREAD);
 * options.z: the luminance test's σ; options.w = 1: low_image = (light rgb, the variance of its
 * luminance) and no scalar (a pixel's world light, bvh_direct.glsl), low_variance unread.
 * low_variance.z < 0 at a traced cell: −its reach (bvh_gather.glsl), kept through the passes;
 * a tap is then weighed by exp(−(|p_q − p| / (REACH · R))²), R the smaller of the two cells'
 * reaches (denoise.py _reach_weight; a cell without one, 0, bounds no tap of its own); a hole
 * the pass fills takes its taps' harmonic mean reach by the light's weights, Σ w / Σ w / R_q (a
 * tap without one counting as infinitely far).
 * A cell whose low_variance.z is 1 is a hole (the sparse gather left it out: denoise.py
 * atrous_filter(holes=…)): no tap, never settled, its taps compared with its traced 3 × 3
 * neighbours' light on its surface (denoise.py _hole_guide; by geometry alone where their
 * weights come to GUIDE_WEIGHT or less; the code only in the DENOISE_HOLES variant, which
 * gpu_gather.denoise runs over a grid with holes); the pass writes its fit and
 * variance.z = 0.
 * options.w = 2: low_variance.w is 1 at the cells whose light no pass shows (a metal's: the
 * sparse gather drew its AO alone, denoise.py atrous_filter(unseen=…)); they are no taps of
 * the light of the cells that show it (their AO still is), and the flag is kept. */
const float KERNEL[5] = float[5](1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);
const vec3 LUMINANCE = vec3(0.2126, 0.7152, 0.0722);

/* The spikes spread before the passes (denoise.py spread_spikes), options.w = 3 then 4:
 * 3 writes per cell (the light it gives: rgb × its excess over the luminance of the
 * brightest of its 3 × 3 neighbours on its surface (weight above SAME_SURFACE); the sum of
 * KERNEL × its same-surface weights over its 5 × 5 window) and (its variance where it gives,
 * else 0); 4 reads the values and variances in low_image / low_variance and those in
 * spread_image / spread_variance, and writes each cell's light less what it gives plus its
 * share of what each giver of its window gives, its variance plus that share of theirs. */

/* The same-surface weight of the point (pc, nc) seen from (pq, nq): the filter's geometry
 * terms, max(n·n_c, 0)^32 × exp(−(|n·(p_c − p)| / (0.1 |p_c − p| + 1e-4))²) (denoise.py
 * _surface_weight). */
float surface_weight(vec3 pq, vec3 nq, vec3 pc, vec3 nc)
{
  vec3 offset = pc - pq;
  float plane = abs(dot(nq, offset));
  float tol = 0.1 * length(offset) + 1e-4;
  float c = max(dot(nq, nc), 0.0); /* c^32 by five squarings: pow is a log and an exp */
  c *= c;
  c *= c;
  c *= c;
  c *= c;
  c *= c;
  return c * exp(-(plane / tol) * (plane / tol));
}

/* The G-buffer point of cell c (position .w < 0.5: it sees nothing) and its normal. */
vec4 cell_point(ivec2 c, ivec2 low, int stride, ivec2 full, out vec3 normal)
{
  ivec2 px = traced_pixel(low.y - 1 - c.y, c.x, stride, full);
  normal = texelFetch(gbuffer_normal, px, 0).xyz;
  return texelFetch(gbuffer_position, px, 0);
}

void spread(ivec2 cell, ivec2 low, int stride, ivec2 full, bool give)
{
  vec4 v = texelFetch(low_image, cell, 0);
  vec4 var = texelFetch(low_variance, cell, 0);
  vec3 n;
  vec4 position = cell_point(cell, low, stride, full, n);
  if (position.w < 0.5) {
    imageStore(out_image, cell, give ? vec4(0.0) : v);
    imageStore(out_variance, cell, give ? vec4(0.0) : var);
    return;
  }
  if (give) {
    float light = dot(v.rgb, LUMINANCE);
    float near = 0.0, total = 0.0; /* the brightest same-surface neighbour's light */
    for (int a = -2; a <= 2; a++) {
      for (int b = -2; b <= 2; b++) {
        ivec2 q = cell + ivec2(b, a);
        if (q.x < 0 || q.y < 0 || q.x >= low.x || q.y >= low.y) {
          continue;
        }
        vec3 nq;
        vec4 pq = cell_point(q, low, stride, full, nq);
        float g = pq.w < 0.5 ? 0.0 : surface_weight(position.xyz, n, pq.xyz, nq);
        total += KERNEL[a + 2] * KERNEL[b + 2] * g;
        if (abs(a) <= 1 && abs(b) <= 1 && (a != 0 || b != 0) && g > SAME_SURFACE) {
          near = max(near, dot(texelFetch(low_image, q, 0).rgb, LUMINANCE));
        }
      }
    }
    float excess = max(light - near, 0.0);
    vec3 given = light > 0.0 ? v.rgb * (excess / light) : vec3(0.0);
    imageStore(out_image, cell, vec4(given, total));
    imageStore(out_variance, cell, vec4(excess > 0.0 ? var.x : 0.0, 0.0, 0.0, 0.0));
    return;
  }
  vec3 light = v.rgb - texelFetch(spread_image, cell, 0).rgb;
  float light_var = var.x;
  for (int a = -2; a <= 2; a++) {
    for (int b = -2; b <= 2; b++) {
      ivec2 q = cell - ivec2(b, a); /* the giver whose window holds this cell at (a, b) */
      if (q.x < 0 || q.y < 0 || q.x >= low.x || q.y >= low.y) {
        continue;
      }
      vec4 given = texelFetch(spread_image, q, 0);
      if (given.a <= 0.0) {
        continue;
      }
      vec3 nq;
      vec3 pq = cell_point(q, low, stride, full, nq).xyz; /* a giver sees a surface */
      float share = KERNEL[a + 2] * KERNEL[b + 2] * surface_weight(pq, nq, position.xyz, n) /
                    given.a;
      light += share * given.rgb;
      light_var += share * texelFetch(spread_variance, q, 0).x;
    }
  }
  imageStore(out_image, cell, vec4(light, v.a));
  imageStore(out_variance, cell, vec4(light_var, var.yzw));
}

/* A cell's −reach as the pass writes it on (a hole's flag: 0). */
float reach_of(vec4 variance)
{
  return min(variance.z, 0.0);
}

/* KERNEL at t ∈ [−2, 2] taps from the centre, linearly interpolated between its taps: the
 * two lines through its taps 3/8, 1/4, 1/16 (no array read: llvmpipe indexes an array in
 * memory) */
float kernel_at(float t)
{
  float x = min(abs(t), 2.0);
  return x <= 1.0 ? 0.375 - 0.125 * x : 0.25 - 0.1875 * (x - 1.0);
}

/* The fit's row from the sums m = Σ w·(1, s, u), m2 = Σ w·(s², su, u²) (the value is
 * row · Σ w·(1, s, u)·value), and its variance from q, q2 (the same sums of w²·var). */
void fit_row(vec3 m, vec3 m2, vec3 q, vec3 q2, out vec3 row, out float variance)
{
  float damp = RIDGE * (m2.x + m2.z) * 0.5 + 1e-4 * m.x; /* (denoise.py _fit) */
  float ma = m2.x + damp, mb = m2.y, mc = m2.z + damp;
  row = vec3(ma * mc - mb * mb, m.z * mb - m.y * mc, m.y * mb - m.z * ma);
  float det = dot(m, row);
  row /= det > 0.0 ? det : 1.0;
  if (options.x < 0.5) { /* the weighted mean (denoise.py fit=False) */
    row = vec3(1.0 / m.x, 0.0, 0.0);
  }
  variance = row.x * row.x * q.x + row.y * row.y * q2.x + row.z * row.z * q2.z +
             2.0 * (row.x * row.y * q.y + row.x * row.z * q.z + row.y * row.z * q2.y);
}

void main()
{
  ivec2 cell = ivec2(gl_GlobalInvocationID.xy);
  ivec2 low = textureSize(low_image, 0);
  if (cell.x >= low.x || cell.y >= low.y) {
    return;
  }
  int stride = int(grid.x);
  ivec2 full = ivec2(grid.yz);
  int step = int(grid.w);
  if (options.w > 2.5) {
    spread(cell, low, stride, full, options.w < 3.5);
    return;
  }
  bool alpha_variance = options.w > 0.5 && options.w < 1.5; /* a pixel's world light */
  bool flagged = options.w > 1.5; /* low_variance.w: the light is not shown there */
  vec4 centre = texelFetch(low_image, cell, 0);
  vec4 centre_var = alpha_variance ? vec4(centre.a, 0.0, 0.0, 0.0) : texelFetch(low_variance, cell, 0);
  centre.a = alpha_variance ? 0.0 : centre.a;
  ivec2 px = traced_pixel(low.y - 1 - cell.y, cell.x, stride, full);
  vec4 position = texelFetch(gbuffer_position, px, 0);
  if (position.w < 0.5) {
    imageStore(out_image, cell, centre);
    imageStore(out_variance, cell, centre_var);
    return;
  }
  vec3 n = texelFetch(gbuffer_normal, px, 0).xyz;
  bool hole = centre_var.z > 0.5;
  bool shown = !(flagged && centre_var.w > 0.5);
  vec2 signal = vec2(dot(centre.rgb, LUMINANCE), centre.a);
  /* The variance prefiltered over the valid 3 × 3 neighbours (denoise.py _blurred). */
  vec2 blurred = vec2(0.0);
  float blur_weight = 0.0;
  vec2 guide = vec2(0.0); /* a hole's: its traced neighbours' light on its surface */
  vec2 guide_squares = vec2(0.0);
  float guide_weight = 0.0;
  for (int a = -1; a <= 1; a++) {
    for (int b = -1; b <= 1; b++) {
      ivec2 q = cell + ivec2(b, a);
      if (q.x < 0 || q.y < 0 || q.x >= low.x || q.y >= low.y) {
        continue;
      }
      ivec2 qpx = traced_pixel(low.y - 1 - q.y, q.x, stride, full);
      vec4 pq = texelFetch(gbuffer_position, qpx, 0);
      if (pq.w < 0.5) {
        continue;
      }
      vec4 qvar = alpha_variance ? vec4(texelFetch(low_image, q, 0).a, 0.0, 0.0, 0.0)
                                 : texelFetch(low_variance, q, 0);
      if (qvar.z > 0.5) {
        continue; /* a hole: no variance of its own */
      }
      float g = (a == 0 ? 0.5 : 0.25) * (b == 0 ? 0.5 : 0.25);
      blurred += g * qvar.xy;
      blur_weight += g;
#ifdef DENOISE_HOLES
      if (hole) {
        float sw = g * surface_weight(position.xyz, n, pq.xyz, texelFetch(gbuffer_normal, qpx, 0).xyz);
        vec4 vq = texelFetch(low_image, q, 0);
        vec2 sq = vec2(dot(vq.rgb, LUMINANCE), alpha_variance ? 0.0 : vq.a);
        guide += sw * sq;
        guide_squares += sw * sq * sq;
        guide_weight += sw;
      }
#endif
    }
  }
  blurred = blur_weight > 0.0 ? blurred / blur_weight : centre_var.xy;
  /* a hole without a guide weighs its taps by geometry alone */
  bool guided = hole && guide_weight > GUIDE_WEIGHT;
  signal = guided ? guide / guide_weight : signal;
  /* the neighbours' spread about the guide: noise the hole's taps may differ by besides their
   * own (denoise.py _hole_guide) */
  vec2 guide_spread = guided ? max(guide_squares / guide_weight - signal * signal, vec2(0.0)) :
                               vec2(0.0);
  bool unguided = hole && !guided;
  bvec2 settled = lessThanEqual(sqrt(max(blurred, vec2(0.0))), settle.x * abs(signal));
  settled = hole ? bvec2(false) : settled;
  if (all(settled)) { /* both kept as they are: no tap changes them (the loop below skips both) */
    imageStore(out_image, cell, centre);
    imageStore(out_variance, cell, vec4(centre_var.xy, reach_of(centre_var),
                                        flagged ? centre_var.w : 0.0));
    return;
  }
  /* The local linear fit (denoise.py _fit): per signal the weighted sums of (1, s, u) ⊗ (1,
   * s, u) over the taps, (s, u) the tap's place in the 5 × 5 window, those of w²·var
   * for the variance, and Σ w·(1, s, u)·value. Vectors, not arrays: llvmpipe keeps an array
   * that a loop indexes in memory, and the sums were 60% of the pass's time. */
  vec3 m_light = vec3(0.0), m2_light = vec3(0.0); /* Σ w·(1, s, u), Σ w·(s², su, u²) */
  vec3 m_scalar = vec3(0.0), m2_scalar = vec3(0.0);
  vec3 q_light = vec3(0.0), q2_light = vec3(0.0); /* the same of w²·var_q */
  vec3 q_scalar = vec3(0.0), q2_scalar = vec3(0.0);
  vec3 light0 = vec3(0.0), light1 = vec3(0.0), light2 = vec3(0.0);
  vec3 scalar = vec3(0.0);
  float nearness = 0.0; /* Σ w / R_q of the light's taps: a hole's reach once filled */
  int spread = int(options.y); /* the kernel stretched over spread × its width (holes: 2) */
  int reach = 2 * spread;
  for (int a = -reach; a <= reach; a++) {
    for (int b = -reach; b <= reach; b++) {
      ivec2 qc = cell + ivec2(b, a) * step;
      if (qc.x < 0 || qc.y < 0 || qc.x >= low.x || qc.y >= low.y) {
        continue;
      }
      ivec2 qpx = traced_pixel(low.y - 1 - qc.y, qc.x, stride, full);
      vec4 pq = texelFetch(gbuffer_position, qpx, 0);
      if (pq.w < 0.5) {
        continue;
      }
      vec3 nq = texelFetch(gbuffer_normal, qpx, 0).xyz;
      vec4 vq = texelFetch(low_image, qc, 0);
      vec4 var4 = alpha_variance ? vec4(vq.a, 0.0, 0.0, 0.0) : texelFetch(low_variance, qc, 0);
      vq.a = alpha_variance ? 0.0 : vq.a;
      if (var4.z > 0.5) {
        continue; /* a hole is no tap */
      }
      vec2 varq = var4.xy;
      float geometry = kernel_at(float(a) / float(spread)) * kernel_at(float(b) / float(spread)) *
                       surface_weight(position.xyz, n, pq.xyz, nq);
      if (centre_var.z < 0.0) { /* within the reach of both (denoise.py _reach_weight) */
        float r = var4.z < 0.0 ? min(-centre_var.z, -var4.z) : -centre_var.z;
        vec3 offset = (pq.xyz - position.xyz) / (REACH * r);
        geometry *= exp(-dot(offset, offset));
      }
      vec2 scale = options.z * sqrt(max(blurred + varq + guide_spread, vec2(0.0))) + 1e-6;
      vec2 t = abs(vec2(dot(vq.rgb, LUMINANCE), vq.a) - signal) / scale;
      /* the light's weight takes the AO's test too, widened by AO_TOLERANCE (denoise.py: an
       * occlusion's edge is the light's): one exp of the two tests' sum */
      t.x += abs(vq.a - signal.y) / (scale.y + AO_TOLERANCE);
      vec2 w = unguided ? vec2(geometry) : geometry * exp(-t);
      w.x = (shown && flagged && var4.w > 0.5) ? 0.0 : w.x;
      float s = float(b) / float(spread); /* the tap's place in the window */
      float u = float(a) / float(spread);
      vec3 linear = vec3(1.0, s, u);
      vec3 square = vec3(s * s, s * u, u * u);
#ifdef DENOISE_HOLES
      nearness += var4.z < 0.0 ? w.x / -var4.z : 0.0; /* (only a hole's reach reads it) */
#endif
      m_light += w.x * linear;
      m2_light += w.x * square;
      m_scalar += w.y * linear;
      m2_scalar += w.y * square;
      q_light += w.x * w.x * varq.x * linear;
      q2_light += w.x * w.x * varq.x * square;
      q_scalar += w.y * w.y * varq.y * linear;
      q2_scalar += w.y * w.y * varq.y * square;
      light0 += w.x * vq.rgb;
      light1 += w.x * s * vq.rgb;
      light2 += w.x * u * vq.rgb;
      scalar += w.y * vec3(1.0, s, u) * vq.a;
    }
  }
  vec4 result = centre;
  vec2 result_var = centre_var.xy;
  vec3 row;
  float variance;
  if (m_light.x > 0.0 && !settled.x) {
    fit_row(m_light, m2_light, q_light, q2_light, row, variance);
    result.rgb = max(row.x * light0 + row.y * light1 + row.z * light2, vec3(0.0));
    result_var.x = max(variance, 0.0);
  }
  if (m_scalar.x > 0.0 && !settled.y) {
    fit_row(m_scalar, m2_scalar, q_scalar, q2_scalar, row, variance);
    result.a = max(dot(row, scalar), 0.0);
    result_var.y = max(variance, 0.0);
  }
  imageStore(out_image, cell, result);
  /* a hole stays one only where no tap could fill it (then left at 0, as numpy's) */
  bool filled = hole && m_light.x > 0.0 && m_scalar.x > 0.0;
  float kept_reach = filled ? (nearness > 0.0 ? -m_light.x / nearness : 0.0) : reach_of(centre_var);
  imageStore(out_variance, cell, vec4(result_var, hole && !filled ? 1.0 : kept_reach,
                                     flagged ? centre_var.w : 0.0));
}

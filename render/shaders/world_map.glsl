/* The world's table (voxgi_addon/gi/world_light.py world_table; sampler `world_map`: the map
 * with its CDFs, the unshadowed-irradiance table and a header row), read: bvh_lights.glsl's
 * world as a light, and world_given.glsl. Needs M_PI_F (sampling.glsl). */

vec4 world_header()
{
  return texelFetch(world_map, ivec2(0, textureSize(world_map, 0).y - 1), 0);
}

bool world_on()
{
  return texelFetch(world_map, ivec2(1, textureSize(world_map, 0).y - 1), 0).x > 0.5;
}

/* A uniform world (its map one colour: world_light.WorldLight.uniform): the cosine's or the
 * lobe's rays alone, its map's importance being uniform over the sphere. */
bool world_uniform()
{
  return texelFetch(world_map, ivec2(1, textureSize(world_map, 0).y - 1), 0).z > 0.5;
}

/* Pixel (row, column) of unit direction d (scene/equirect.direction_to_pixel). */
ivec2 world_pixel(vec3 d, int h, int w)
{
  float el = asin(clamp(d.z, -1.0, 1.0));
  float phi = (d.x == 0.0 && d.y == 0.0) ? 0.0 : atan(d.y, d.x);
  int i = clamp(int(floor((M_PI_F / 2.0 - el) * float(h) / M_PI_F)), 0, h - 1);
  int j = int(floor((phi + M_PI_F) * float(w) / (2.0 * M_PI_F)));
  j = ((j % w) + w) % w;
  return ivec2(i, j);
}

vec3 world_radiance_at(ivec2 pixel)
{
  return texelFetch(world_map, ivec2(pixel.y, pixel.x), 0).rgb;
}

/* E(n)/π: bilinear lookup of the irradiance table, rows from the zenith to the nadir
 * inclusive (world_light.unshadowed). */
vec3 world_unshadowed(vec3 n, int h)
{
  int ih = int(world_header().z);
  int iw = 2 * ih;
  float el = asin(clamp(n.z, -1.0, 1.0));
  float phi = (n.x == 0.0 && n.y == 0.0) ? 0.0 : atan(n.y, n.x); /* numpy's arctan2(0, 0) */
  float y = clamp((M_PI_F / 2.0 - el) * float(ih - 1) / M_PI_F, 0.0, float(ih) - 1.0);
  float x = (phi + M_PI_F) * float(iw) / (2.0 * M_PI_F) - 0.5;
  int y0 = min(int(floor(y)), ih - 2);
  int y1 = y0 + 1;
  float x0f = floor(x);
  float fy = y - float(y0);
  float fx = x - x0f;
  int x0 = ((int(x0f) % iw) + iw) % iw;
  int x1 = (x0 + 1) % iw;
  vec3 top = texelFetch(world_map, ivec2(x0, h + y0), 0).rgb * (1.0 - fx) +
             texelFetch(world_map, ivec2(x1, h + y0), 0).rgb * fx;
  vec3 bottom = texelFetch(world_map, ivec2(x0, h + y1), 0).rgb * (1.0 - fx) +
                texelFetch(world_map, ivec2(x1, h + y1), 0).rgb * fx;
  return top * (1.0 - fy) + bottom * fy;
}

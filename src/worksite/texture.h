// Procedural textures for the renderer (internal): value noise and the materials' albedo.
// Everything is a pure function of its arguments, so images are reproducible.
#pragma once

#include <cmath>
#include <cstdint>

namespace teachsim::worksite::internal {

inline std::uint32_t Hash3(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  std::uint32_t h = seed * 0x9E3779B1u;
  h ^= static_cast<std::uint32_t>(x) * 0x85EBCA77u;
  h ^= static_cast<std::uint32_t>(y) * 0xC2B2AE3Du;
  h ^= static_cast<std::uint32_t>(z) * 0x27D4EB2Fu;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 12;
  h *= 0x297A2D39u;
  h ^= h >> 15;
  return h;
}

inline float HashUnit(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  return static_cast<float>(Hash3(x, y, z, seed) >> 8) * (1.0f / 16777216.0f);
}

// Smooth value noise in [0, 1): trilinear over a hashed integer lattice with a smoothstep fade.
inline float ValueNoise(float x, float y, float z, std::uint32_t seed) {
  const float fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  const std::int32_t ix = static_cast<std::int32_t>(fx), iy = static_cast<std::int32_t>(fy),
                     iz = static_cast<std::int32_t>(fz);
  float tx = x - fx, ty = y - fy, tz = z - fz;
  tx = tx * tx * (3 - 2 * tx);
  ty = ty * ty * (3 - 2 * ty);
  tz = tz * tz * (3 - 2 * tz);
  auto lerp = [](float a, float b, float t) { return a + (b - a) * t; };
  const float c000 = HashUnit(ix, iy, iz, seed), c100 = HashUnit(ix + 1, iy, iz, seed);
  const float c010 = HashUnit(ix, iy + 1, iz, seed), c110 = HashUnit(ix + 1, iy + 1, iz, seed);
  const float c001 = HashUnit(ix, iy, iz + 1, seed), c101 = HashUnit(ix + 1, iy, iz + 1, seed);
  const float c011 = HashUnit(ix, iy + 1, iz + 1, seed), c111 = HashUnit(ix + 1, iy + 1, iz + 1, seed);
  return lerp(lerp(lerp(c000, c100, tx), lerp(c010, c110, tx), ty),
              lerp(lerp(c001, c101, tx), lerp(c011, c111, tx), ty), tz);
}

// Wood: growth rings about an axis (u, v are the coordinates across it, a along it, metres,
// object frame), wobbled by noise, plus fine streaks along the grain and broad colour patches.
// Returns a factor around 1 that multiplies the albedo.
inline float WoodFactor(float a, float u, float v, float ring_centre_u, float ring_centre_v,
                        std::uint32_t seed) {
  const float du = u - ring_centre_u, dv = v - ring_centre_v;
  const float wobble = ValueNoise(a * 30.0f, u * 30.0f, v * 30.0f, seed) - 0.5f;
  const float r = std::sqrt(du * du + dv * dv) + 0.004f * wobble;
  const float phase = r * (1.0f / 0.0026f);  // rings about 2.6 mm apart
  const float s = 0.5f + 0.5f * std::sin(6.2831853f * phase);
  const float late = s * s * s * s;  // dark late-wood: narrow bands
  const float streak = ValueNoise(a * 12.0f, u * 450.0f, v * 450.0f, seed + 1) - 0.5f;
  const float patch = ValueNoise(a * 20.0f, u * 20.0f, v * 20.0f, seed + 2) - 0.5f;
  return 1.0f - 0.34f * late + 0.2f * streak + 0.14f * patch + 0.1f;
}

// The table: broad mottling plus fine grit (x, y on the table top, metres).
inline float TableFactor(float x, float y, std::uint32_t seed) {
  const float broad = ValueNoise(x * 9.0f, y * 9.0f, 0.5f, seed) - 0.5f;
  const float medium = ValueNoise(x * 40.0f, y * 40.0f, 3.5f, seed + 1) - 0.5f;
  const float grit = ValueNoise(x * 400.0f, y * 400.0f, 7.5f, seed + 2) - 0.5f;
  return 1.0f + 0.09f * broad + 0.07f * medium + 0.06f * grit;
}

}  // namespace teachsim::worksite::internal

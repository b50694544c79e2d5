// A triangle surface for the tests of embedded surfaces (core, live).
#pragma once

#include <cmath>
#include <numbers>

#include "core/mesh.hpp"

namespace tactile::test {

// A closed UV sphere of `around` x `rings` quads split in two (poles fanned), wound outward.
inline SurfaceMesh make_uv_sphere(const Vec3& centre, double radius, int around, int rings) {
  SurfaceMesh s;
  s.vertices.push_back(centre + Vec3(0, radius, 0));
  for (int r = 1; r < rings; ++r) {
    const double theta = std::numbers::pi * r / rings;
    for (int a = 0; a < around; ++a) {
      const double phi = 2 * std::numbers::pi * a / around;
      s.vertices.push_back(
          centre + radius * Vec3(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi)));
    }
  }
  s.vertices.push_back(centre - Vec3(0, radius, 0));
  const int south = int(s.vertices.size()) - 1;
  auto ring = [&](int r, int a) { return 1 + (r - 1) * around + (a % around); };
  for (int a = 0; a < around; ++a) s.triangles.push_back({0, ring(1, a + 1), ring(1, a)});
  for (int r = 1; r + 1 < rings; ++r)
    for (int a = 0; a < around; ++a) {
      s.triangles.push_back({ring(r, a), ring(r, a + 1), ring(r + 1, a + 1)});
      s.triangles.push_back({ring(r, a), ring(r + 1, a + 1), ring(r + 1, a)});
    }
  for (int a = 0; a < around; ++a) s.triangles.push_back({south, ring(rings - 1, a), ring(rings - 1, a + 1)});
  return s;
}

}  // namespace tactile::test

#include "app/section.hpp"

#include <glm/geometric.hpp>

namespace tactile {

SectionCut make_section_cut(const TetMesh& mesh, const SectionPlane& plane) {
  SectionCut cut;
  cut.first.push_back(0);
  const Vec3 n = glm::normalize(plane.normal);
  for (const Tet& t : mesh.tets) {
    double d[4];
    int above[4], n_above = 0, below[4], n_below = 0;
    for (int k = 0; k < 4; ++k) {
      d[k] = glm::dot(mesh.X[size_t(t[size_t(k)])] - plane.point, n);
      if (d[k] >= 0)
        above[n_above++] = k;
      else
        below[n_below++] = k;
    }
    if (n_above == 0 || n_below == 0) continue;
    // Corner on edge (i below, j above): s where the distance is 0, in (0, 1].
    auto corner = [&](int i, int j) { cut.corners.push_back({t[size_t(i)], t[size_t(j)], d[i] / (d[i] - d[j])}); };
    if (n_below == 1) {
      for (int k = 0; k < 3; ++k) corner(below[0], above[k]);
    } else if (n_above == 1) {
      for (int k = 0; k < 3; ++k) corner(below[k], above[0]);
    } else {  // 2 + 2: a quadrilateral; consecutive corners share a node
      corner(below[0], above[0]);
      corner(below[0], above[1]);
      corner(below[1], above[1]);
      corner(below[1], above[0]);
    }
    cut.first.push_back(int32_t(cut.corners.size()));
  }
  return cut;
}

double compute_section_area(const SectionCut& cut, const TetMesh& mesh, const std::vector<double>& u) {
  auto position = [&](int32_t i) {
    const Vec3& X = mesh.X[size_t(i)];
    if (u.empty()) return X;
    const size_t j = 3 * size_t(i);
    return X + Vec3(u[j], u[j + 1], u[j + 2]);
  };
  double area = 0;
  Vec3 x[4];
  for (size_t k = 0; k + 1 < cut.first.size(); ++k) {
    const int32_t n = cut.first[k + 1] - cut.first[k];
    for (int32_t c = 0; c < n; ++c) {
      const SectionCut::Corner& q = cut.corners[size_t(cut.first[k] + c)];
      const Vec3 xa = position(q.a);
      x[c] = xa + q.s * (position(q.b) - xa);
    }
    // Vector area of a planar polygon, fanned from corner 0.
    Vec3 a(0.0);
    for (int32_t c = 1; c + 1 < n; ++c) a += glm::cross(x[c] - x[0], x[c + 1] - x[0]);
    area += 0.5 * glm::length(a);
  }
  return area;
}

}  // namespace tactile

// Material cross-sections: exact areas at rest and the laws they follow
// under rigid and affine motions.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <glm/geometric.hpp>

#include "app/section.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

// u = A X + b at every node (n_nodes x 3) for a 3x3 matrix A given by rows.
std::vector<double> affine_displacement(const TetMesh& m, const double A[9], const Vec3& b) {
  std::vector<double> u(3 * size_t(m.n_nodes()));
  for (size_t i = 0; i < size_t(m.n_nodes()); ++i) {
    const Vec3& X = m.X[i];
    for (int r = 0; r < 3; ++r)
      u[3 * i + size_t(r)] = A[3 * r] * X.x + A[3 * r + 1] * X.y + A[3 * r + 2] * X.z + b[r] - X[r];
  }
  return u;
}

TEST(Section, RestAreaOfABoxIsItsCrossSection) {
  for (BoxSplit split : {BoxSplit::kuhn6, BoxSplit::centred24}) {
    const TetMesh m = make_box(Vec3(-0.05, 0, -0.1), Vec3(0.05, 0.3, 0.1), {3, 6, 4}, split);
    // On a layer of nodes (faces lie in the plane: each counted once) and between layers.
    for (double y : {0.15, 0.1234, 0.05}) {
      const SectionCut cut = make_section_cut(m, SectionPlane{"s", Vec3(0, y, 0), Vec3(0, 1, 0)});
      EXPECT_NEAR(compute_section_area(cut, m, {}), 0.1 * 0.2, 1e-14) << "y = " << y;
    }
    // A plane oblique to the box: a rectangle 0.1 wide and 0.2 / cos(30 deg) long.
    const Vec3 n(0, std::cos(std::numbers::pi / 6), std::sin(std::numbers::pi / 6));
    const SectionCut cut = make_section_cut(m, SectionPlane{"o", Vec3(0, 0.15, 0), n});
    EXPECT_NEAR(compute_section_area(cut, m, {}), 0.1 * 0.2 / std::cos(std::numbers::pi / 6), 1e-13);
  }
}

TEST(Section, RigidMotionKeepsTheAreaAndAffineMapsScaleIt) {
  const TetMesh m = make_cylinder(0.1, 0.3, 16, 6, 2);
  const SectionCut cut = make_section_cut(m, SectionPlane{"mid", Vec3(0, 0.13, 0), Vec3(0, 1, 0)});
  const double rest = compute_section_area(cut, m, {});
  EXPECT_NEAR(rest, 8.0 * 0.01 * std::sin(2 * std::numbers::pi / 16), 1e-14);  // the 16-gon

  // A rotation by 0.87 rad about (1, 2, 3) (Rodrigues, applied to the basis) and a shift.
  const Vec3 k = glm::normalize(Vec3(1, 2, 3));
  double R[9];
  for (int j = 0; j < 3; ++j) {
    Vec3 e(0.0);
    e[j] = 1;
    const Vec3 col = e * std::cos(0.87) + glm::cross(k, e) * std::sin(0.87) + k * glm::dot(k, e) * (1 - std::cos(0.87));
    for (int i = 0; i < 3; ++i) R[3 * i + j] = col[i];
  }
  EXPECT_NEAR(compute_section_area(cut, m, affine_displacement(m, R, Vec3(1, -2, 0.5))), rest, 1e-13);

  // x = A X scales an area with unit normal N by det(A) |A^-T N|: for diag(2, 0.5, 3) and N = y, by 6.
  const double A[9] = {2, 0, 0, 0, 0.5, 0, 0, 0, 3};
  EXPECT_NEAR(compute_section_area(cut, m, affine_displacement(m, A, Vec3(0.0))), 6 * rest, 1e-13);
  // A shear in the plane's own direction keeps it.
  const double S[9] = {1, 0.7, 0, 0, 1, 0, 0, -0.4, 1};
  EXPECT_NEAR(compute_section_area(cut, m, affine_displacement(m, S, Vec3(0.0))), rest, 1e-13);
}

TEST(Section, APlaneBesideTheBodyCutsNothing) {
  const TetMesh m = make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2});
  const SectionCut cut = make_section_cut(m, SectionPlane{"out", Vec3(0, 2, 0), Vec3(0, 1, 0)});
  EXPECT_EQ(cut.first.size(), 1u);
  EXPECT_EQ(compute_section_area(cut, m, {}), 0.0);
}

}  // namespace
}  // namespace tactile

#include "mesh/primitives.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "mesh/quality.hpp"
#include "mesh/test_files.hpp"

namespace tactile {
namespace {

using test::compute_mesh_volume;
using test::count_nonpositive_tets;
using test::count_open_edges;

// Sum of the boundary faces' areas, and the divergence-theorem volume
// (1/3) sum (centroid . n) A, which equals the mesh volume only when every
// face is wound outwards.
struct BoundarySums {
  double area = 0.0, flux_volume = 0.0;
};
BoundarySums compute_boundary_sums(const TetMesh& m, const std::vector<Tri>& faces) {
  BoundarySums s;
  for (const Tri& f : faces) {
    const Vec3 &a = m.X[size_t(f[0])], &b = m.X[size_t(f[1])], &c = m.X[size_t(f[2])];
    const Vec3 n2 = glm::cross(b - a, c - a);  // 2 A n
    s.area += 0.5 * glm::length(n2);
    s.flux_volume += glm::dot((a + b + c) / 3.0, n2) / 6.0;
  }
  return s;
}

TEST(MakeBox, VolumeIsTheBoxVolumeAndAllTetsArePositive) {
  const Vec3 lo(-0.5, 0.25, 1.0), hi(1.5, 0.75, 1.25);  // 2 x 0.5 x 0.25
  const TetMesh m = make_box(lo, hi, {8, 3, 2});
  EXPECT_EQ(m.n_nodes(), 9 * 4 * 3);
  EXPECT_EQ(m.n_tets(), 8 * 3 * 2 * 6);
  EXPECT_EQ(check_mesh_structure(m), "");
  EXPECT_EQ(count_nonpositive_tets(m), 0);
  EXPECT_NEAR(compute_mesh_volume(m), 0.25, 0.25 * 1e-14);
  const Aabb box = compute_aabb(m.X);
  EXPECT_EQ(box.lo, lo);  // corners exact
  EXPECT_EQ(box.hi, hi);
}

TEST(MakeBox, BoundaryIsAClosedSurfaceWithTheBoxArea) {
  for (BoxSplit split : {BoxSplit::kuhn6, BoxSplit::centred24}) {
    SCOPED_TRACE(split == BoxSplit::kuhn6 ? "kuhn6" : "centred24");
    const TetMesh m = make_box(Vec3(0.0), Vec3(2.0, 1.0, 0.5), {4, 3, 5}, split);
    const std::vector<Tri> faces = compute_boundary_faces(m);
    EXPECT_EQ(count_open_edges(faces), 0);
    const BoundarySums s = compute_boundary_sums(m, faces);
    // A non-conforming mesh would leave inner faces over, adding area.
    EXPECT_NEAR(s.area, 2.0 * (2.0 * 1.0 + 1.0 * 0.5 + 0.5 * 2.0), 1e-12);
    EXPECT_NEAR(s.flux_volume, 1.0, 1e-12);
  }
}

TEST(MakeBox, Centred24SplitIsPositiveWithExactVolume) {
  const TetMesh m = make_box(Vec3(0.0), Vec3(1.0, 0.5, 0.25), {3, 2, 2}, BoxSplit::centred24);
  const int cells = 3 * 2 * 2;
  EXPECT_EQ(m.n_tets(), 24 * cells);
  EXPECT_EQ(m.n_nodes(), 4 * 3 * 3 + (4 * 2 * 2 + 3 * 3 * 2 + 3 * 2 * 3) + cells);
  EXPECT_EQ(check_mesh_structure(m), "");
  EXPECT_EQ(count_nonpositive_tets(m), 0);
  EXPECT_NEAR(compute_mesh_volume(m), 0.125, 1e-15);
}

TEST(MakeBox, KuhnTetsHaveDihedralAnglesOf45To90Degrees) {
  const MeshQuality q = compute_quality(make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2}));
  EXPECT_NEAR(q.min_dihedral_deg, 45.0, 1e-9);
  EXPECT_NEAR(q.max_dihedral_deg, 90.0, 1e-9);
  EXPECT_TRUE(q.inverted.empty() && q.degenerate.empty() && q.poor.empty() && q.unreferenced.empty());
}

TEST(MakeBox, RefusesEmptyGridAndEmptyBox) {
  test::expect_mesh_error([] { make_box(Vec3(0.0), Vec3(1.0), {0, 1, 1}); }, {"make_box", "cells"});
  test::expect_mesh_error([] { make_box(Vec3(0.0), Vec3(1.0, 0.0, 1.0), {1, 1, 1}); }, {"make_box", "axis 1"});
}

// Volume of the inscribed n-gon prism, the exact volume of the mesh.
double polygon_prism_volume(double r, double h, int n) {
  return 0.5 * n * r * r * std::sin(2.0 * std::numbers::pi / n) * h;
}

TEST(MakeCylinder, VolumeIsThePolygonPrismAndConvergesToPiR2H) {
  const double r = 0.3, h = 1.2, exact = std::numbers::pi * r * r * h;
  double previous_error = 1.0;
  for (int n : {8, 16, 32, 64}) {
    SCOPED_TRACE(n);
    const TetMesh m = make_cylinder(r, h, n, 6, n / 8 + 1);
    EXPECT_EQ(check_mesh_structure(m), "");
    EXPECT_EQ(count_nonpositive_tets(m), 0);
    const double v = compute_mesh_volume(m);
    EXPECT_NEAR(v, polygon_prism_volume(r, h, n), 1e-12);
    const double error = std::abs(v - exact) / exact;
    EXPECT_LT(error, 0.5 * previous_error);  // O(1/n^2)
    previous_error = error;
  }
  EXPECT_LT(previous_error, 0.002);
}

TEST(MakeCylinder, IsClosedConformingAndAlongY) {
  const TetMesh m = make_cylinder(0.5, 2.0, 24, 5, 3);
  const std::vector<Tri> faces = compute_boundary_faces(m);
  EXPECT_EQ(count_open_edges(faces), 0);
  // Area of the faceted surface: two polygon caps plus n rectangles.
  const double cap = 0.5 * 24 * 0.25 * std::sin(2.0 * std::numbers::pi / 24);
  const double side = 24 * 2.0 * 0.5 * std::sin(std::numbers::pi / 24) * 2.0;
  EXPECT_NEAR(compute_boundary_sums(m, faces).area, 2 * cap + side, 1e-12);
  const Aabb box = compute_aabb(m.X);
  EXPECT_DOUBLE_EQ(box.lo.y, 0.0);
  EXPECT_DOUBLE_EQ(box.hi.y, 2.0);
  EXPECT_NEAR(box.hi.x, 0.5, 1e-15);
  const MeshQuality q = compute_quality(m);
  EXPECT_TRUE(q.degenerate.empty() && q.inverted.empty());
  EXPECT_TRUE(q.unreferenced.empty());
}

TEST(MakeCylinder, RefusesBadArguments) {
  test::expect_mesh_error([] { make_cylinder(0.0, 1.0, 8, 1, 1); }, {"make_cylinder", "radius"});
  test::expect_mesh_error([] { make_cylinder(1.0, 1.0, 2, 1, 1); }, {"make_cylinder", "n_around"});
  test::expect_mesh_error([] { make_cylinder(1.0, 1.0, 6, 1, 40); }, {"make_cylinder", "too large"});
}

TEST(MakeSphere, VolumeConvergesToFourThirdsPiR3) {
  const Vec3 c(0.1, -0.2, 0.3);
  const double r = 0.05, exact = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  double previous_error = 1.0;
  for (int resolution : {1, 2, 3}) {
    SCOPED_TRACE(resolution);
    const TetMesh m = make_sphere(c, r, resolution);
    EXPECT_EQ(check_mesh_structure(m), "");
    EXPECT_EQ(count_nonpositive_tets(m), 0);
    const double error = std::abs(compute_mesh_volume(m) - exact) / exact;
    EXPECT_LT(error, 0.5 * previous_error);
    previous_error = error;
    const Aabb box = compute_aabb(m.X);
    EXPECT_LE(glm::length(box.hi - c), r * std::sqrt(3.0) + 1e-12);
    const MeshQuality q = compute_quality(m);
    EXPECT_TRUE(q.degenerate.empty() && q.inverted.empty());
    EXPECT_GT(q.min_dihedral_deg, 5.0);
  }
  EXPECT_LT(previous_error, 0.02);
}

TEST(MakeSphere, IsDeterministic) {
  const TetMesh a = make_sphere(Vec3(0.0), 1.0, 2), b = make_sphere(Vec3(0.0), 1.0, 2);
  EXPECT_EQ(a.X, b.X);
  EXPECT_EQ(a.tets, b.tets);
}

TEST(MakeSphere, RefusesBadArguments) {
  test::expect_mesh_error([] { make_sphere(Vec3(0.0), -1.0, 1); }, {"make_sphere", "radius"});
  test::expect_mesh_error([] { make_sphere(Vec3(0.0), 1.0, 9); }, {"make_sphere", "resolution"});
}

}  // namespace
}  // namespace tactile

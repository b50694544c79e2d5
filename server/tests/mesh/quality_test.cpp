#include "mesh/quality.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "mesh/test_files.hpp"

namespace tactile {
namespace {

using test::expect_mesh_error;

// Regular tet of edge sqrt(2) on alternate corners of the unit cube.
TetMesh make_regular_tet() {
  TetMesh m;
  m.X = {{0, 0, 0}, {1, 1, 0}, {1, 0, 1}, {0, 1, 1}};
  m.tets = {{0, 1, 2, 3}};
  if (compute_tet_volume(m.X[0], m.X[1], m.X[2], m.X[3]) < 0) std::swap(m.tets[0][1], m.tets[0][2]);
  return m;
}

TEST(Quality, RegularTetHasDihedral70_53AndAspectOne) {
  const MeshQuality q = compute_quality(make_regular_tet());
  const double dihedral = std::acos(1.0 / 3.0) * 180.0 / std::numbers::pi;  // 70.5288 deg
  EXPECT_NEAR(q.min_dihedral_deg, dihedral, 1e-9);
  EXPECT_NEAR(q.max_dihedral_deg, dihedral, 1e-9);
  EXPECT_NEAR(q.min_dihedral_deg, 70.5288, 1e-4);
  EXPECT_NEAR(q.max_aspect_ratio, 1.0, 1e-12);
  EXPECT_NEAR(q.min_volume, 1.0 / 3.0, 1e-15);
  EXPECT_NEAR(q.min_edge, std::sqrt(2.0), 1e-15);
  EXPECT_EQ(q.n_tets, 1);
  EXPECT_EQ(q.n_nodes, 4);
  EXPECT_TRUE(q.inverted.empty() && q.degenerate.empty() && q.poor.empty() && q.unreferenced.empty());
}

TEST(Quality, AspectRatioIsScaleFreeAndGrowsWithStretch) {
  TetMesh m = make_regular_tet();
  for (Vec3& x : m.X) x *= 1e-3;
  EXPECT_NEAR(compute_quality(m).max_aspect_ratio, 1.0, 1e-12);
  for (Vec3& x : m.X) x.z *= 10.0;
  EXPECT_GT(compute_quality(m).max_aspect_ratio, 5.0);
}

// Tet 0 fine, tet 1 inverted, tet 2 flat (four coplanar nodes).
TetMesh make_bad_mesh() {
  TetMesh m;
  m.X = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}};
  m.tets = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 1, 4, 2}};
  return m;
}

TEST(Quality, RefusesInvertedAndFlatTetsNamingBoth) {
  const TetMesh m = make_bad_mesh();
  const MeshQuality q = compute_quality(m);
  EXPECT_EQ(q.inverted, (std::vector<int32_t>{1}));
  EXPECT_EQ(q.degenerate, (std::vector<int32_t>{2}));
  EXPECT_TRUE(q.poor.empty());
  expect_mesh_error([&] { check_mesh_or_throw(m, q); },
                    {"mesh refused", "1 inverted tet (id 1)", "1 degenerate tet (id 2)"});
}

TEST(Quality, NearlyFlatTetIsDegenerateRelativeToItsSize) {
  TetMesh m = make_regular_tet();
  const MeshQuality fine = compute_quality(m);
  EXPECT_TRUE(fine.degenerate.empty());
  // Squash to height 1e-12 m over 1 m edges: |V| / L^3 ~ 1e-13.
  for (Vec3& x : m.X) x.z *= 1e-12;
  EXPECT_EQ(compute_quality(m).degenerate, (std::vector<int32_t>{0}));
  // The same shape at 1 mm is still degenerate: the test is relative.
  for (Vec3& x : m.X) x *= 1e-3;
  EXPECT_EQ(compute_quality(m).degenerate, (std::vector<int32_t>{0}));
}

TEST(Quality, ListsAtMostTenIds) {
  TetMesh m;
  m.X = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.tets.assign(12, Tet{0, 2, 1, 3});  // all inverted
  expect_mesh_error([&] { check_mesh_or_throw(m, compute_quality(m)); },
                    {"12 inverted tets (ids 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, and 2 more)"});
}

TEST(Quality, SliverIsPoorButAccepted) {
  // Four nodes near a square, alternately lifted by +-h: a sliver, with
  // dihedral angles near 0 and 180 degrees but edges of ordinary length.
  const double h = 0.02;
  TetMesh m;
  m.X = {{1, 0, h}, {-1, 0, h}, {0, 1, -h}, {0, -1, -h}};
  m.tets = {{0, 1, 2, 3}};
  if (compute_tet_volume(m.X[0], m.X[1], m.X[2], m.X[3]) < 0) std::swap(m.tets[0][1], m.tets[0][2]);
  const MeshQuality q = compute_quality(m);
  EXPECT_EQ(q.poor, (std::vector<int32_t>{0}));
  EXPECT_TRUE(q.degenerate.empty() && q.inverted.empty());
  EXPECT_LT(q.min_dihedral_deg, 5.0);
  EXPECT_GT(q.max_dihedral_deg, 170.0);
  EXPECT_NO_THROW(check_mesh_or_throw(m, q));
  const std::string summary = q.summary();
  EXPECT_NE(summary.find("1 poor"), std::string::npos) << summary;
  EXPECT_NE(summary.find("warning"), std::string::npos) << summary;
}

TEST(Quality, StructureFaultsAreRefusedBeforeGeometry) {
  TetMesh m = make_regular_tet();
  m.tets.push_back({0, 1, 2, 7});
  const MeshQuality q = compute_quality(m);  // does not read past the nodes
  EXPECT_EQ(q.degenerate, (std::vector<int32_t>{1}));
  expect_mesh_error([&] { check_mesh_or_throw(m, q); }, {"mesh refused", "tet 1 refers to node 7"});
}

TEST(Quality, ReportsUnreferencedNodesAndCompactingDropsThem) {
  TetMesh m;
  m.X = {{9, 9, 9}, {0, 0, 0}, {1, 0, 0}, {8, 8, 8}, {0, 1, 0}, {0, 0, 1}};
  m.tets = {{1, 2, 4, 5}};
  m.region = {4};
  const MeshQuality q = compute_quality(m);
  EXPECT_EQ(q.unreferenced, (std::vector<int32_t>{0, 3}));
  EXPECT_NO_THROW(check_mesh_or_throw(m, q));  // not an error
  EXPECT_NE(q.summary().find("2 unreferenced"), std::string::npos) << q.summary();
  const TetMesh c = compute_compacted(m);
  EXPECT_EQ(c.X, (std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
  EXPECT_EQ(c.tets, (std::vector<Tet>{{0, 1, 2, 3}}));
  EXPECT_EQ(c.region, (std::vector<int32_t>{4}));
  EXPECT_TRUE(compute_quality(c).unreferenced.empty());
}

}  // namespace
}  // namespace tactile

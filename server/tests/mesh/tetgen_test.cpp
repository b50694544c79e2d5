#include "mesh/tetgen.hpp"

#include <gtest/gtest.h>

#include "mesh/quality.hpp"
#include "mesh/test_files.hpp"

namespace tactile {
namespace {

using test::compute_mesh_volume;
using test::count_nonpositive_tets;
using test::expect_mesh_error;
using test::make_cube_surface;

TEST(Tetrahedralize, CubeFillsItsVolumeWithPositiveQualityTets) {
  TetgenOptions options;
  options.max_volume = 0.01;
  options.min_dihedral_deg = 10.0;
  const TetMesh m = tetrahedralize(make_cube_surface(), options);
  EXPECT_EQ(check_mesh_structure(m), "");
  EXPECT_EQ(count_nonpositive_tets(m), 0);
  EXPECT_NEAR(compute_mesh_volume(m), 1.0, 1e-12);
  EXPECT_GE(m.n_tets(), 100);  // the volume bound forces refinement
  const MeshQuality q = compute_quality(m);
  EXPECT_LE(q.max_volume, 0.01 * (1 + 1e-9));
  EXPECT_TRUE(q.degenerate.empty() && q.inverted.empty());
  EXPECT_NO_THROW(check_mesh_or_throw(m, q));
}

TEST(Tetrahedralize, WithoutQualitySwitchesKeepsTheSurfaceNodes) {
  TetgenOptions options;
  options.max_radius_edge_ratio = 0.0;
  const TetMesh m = tetrahedralize(make_cube_surface(), options);
  EXPECT_EQ(m.n_nodes(), 8);
  EXPECT_EQ(count_nonpositive_tets(m), 0);
  EXPECT_NEAR(compute_mesh_volume(m), 1.0, 1e-14);
}

TEST(Tetrahedralize, RefusesAnOpenSurfaceNamingAnEdge) {
  SurfaceMesh s = make_cube_surface();
  const Tri removed = s.triangles.back();
  s.triangles.pop_back();
  try {
    tetrahedralize(s, {});
    ADD_FAILURE() << "open surface accepted";
  } catch (const MeshError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("not closed"), std::string::npos) << msg;
    bool names_edge_of_hole = false;
    for (size_t k = 0; k < 3; ++k) {
      const auto [a, b] = std::minmax(removed[k], removed[(k + 1) % 3]);
      const std::string edge = "edge (" + std::to_string(a) + ", " + std::to_string(b) + ")";
      names_edge_of_hole |= msg.find(edge) != std::string::npos;
    }
    EXPECT_TRUE(names_edge_of_hole) << msg;
  }
}

TEST(Tetrahedralize, RefusesAnEdgeSharedByThreeTriangles) {
  SurfaceMesh s = make_cube_surface();
  s.vertices.emplace_back(0.5, 0.5, 3.0);
  s.triangles.push_back({0, 1, 8});  // a fin on the cube's edge (0, 1)
  expect_mesh_error([&] { tetrahedralize(s, {}); }, {"not closed", "edge (0, 1)", "used by 3 triangles"});
}

TEST(Tetrahedralize, RefusesASelfIntersectingSurfaceNamingTriangles) {
  // Two overlapping cubes in one surface: closed, but their faces cross.
  SurfaceMesh s = make_cube_surface();
  const SurfaceMesh c = make_cube_surface();
  for (const Vec3& v : c.vertices) s.vertices.push_back(v + Vec3(0.5, 0.25, 0.125));
  for (const Tri& t : c.triangles) s.triangles.push_back({t[0] + 8, t[1] + 8, t[2] + 8});
  expect_mesh_error([&] { tetrahedralize(s, {}); }, {"TetGen", "intersects itself", "triangles cross others: "});
  // TetGen's failure left the process sound: the next call works.
  EXPECT_NEAR(compute_mesh_volume(tetrahedralize(make_cube_surface(), {})), 1.0, 1e-12);
}

TEST(Tetrahedralize, RefusesBadInput) {
  SurfaceMesh s = make_cube_surface();
  s.vertices[3].y = std::nan("");
  expect_mesh_error([&] { tetrahedralize(s, {}); }, {"vertex 3", "non-finite"});
  s = make_cube_surface();
  s.triangles[5][1] = 99;
  expect_mesh_error([&] { tetrahedralize(s, {}); }, {"triangle 5", "vertex 99"});
  s = make_cube_surface();
  s.triangles[2][1] = s.triangles[2][0];
  expect_mesh_error([&] { tetrahedralize(s, {}); }, {"triangle 2", "repeats"});
  expect_mesh_error([] { tetrahedralize(SurfaceMesh{}, {}); }, {"0 vertices"});
  TetgenOptions options;
  options.max_volume = -1.0;
  expect_mesh_error([&] { tetrahedralize(make_cube_surface(), options); }, {"max_volume"});
}

}  // namespace
}  // namespace tactile

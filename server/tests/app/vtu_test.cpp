// The hand-written VTK XML output: base64 as RFC 4648 has it, files that are
// XML and hold what they were given.
#include <gtest/gtest.h>

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>

#include "app/vtu.hpp"
#include "app_fixtures.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

TEST(Vtu, Base64MatchesTheRfcVectors) {
  // RFC 4648, section 10.
  const std::pair<const char*, const char*> vectors[] = {{"", ""},
                                                         {"f", "Zg=="},
                                                         {"fo", "Zm8="},
                                                         {"foo", "Zm9v"},
                                                         {"foob", "Zm9vYg=="},
                                                         {"fooba", "Zm9vYmE="},
                                                         {"foobar", "Zm9vYmFy"}};
  for (const auto& [in, out] : vectors) EXPECT_EQ(encode_base64(in, std::strlen(in)), out) << in;
  std::vector<uint8_t> all(256);
  for (int i = 0; i < 256; ++i) all[size_t(i)] = uint8_t(i);
  EXPECT_EQ(test::decode_base64(encode_base64(all.data(), all.size())), all);
}

TEST(Vtu, FrameRoundTrips) {
  test::TempDir dir;
  TetMesh m = make_box(Vec3(0.0), Vec3(1.0, 2.0, 3.0), {1, 2, 1});
  m.region.assign(m.tets.size(), 0);
  m.region[3] = 2;
  std::vector<double> u(3 * size_t(m.n_nodes())), v(u.size()), force(u.size()), density(size_t(m.n_tets()));
  std::vector<uint8_t> fixed(size_t(m.n_nodes()), 0);
  fixed[1] = 1, fixed[2] = 2;
  for (size_t i = 0; i < u.size(); ++i) u[i] = 0.001 * double(i), v[i] = -double(i), force[i] = 0.5 + double(i);
  for (size_t e = 0; e < density.size(); ++e) density[e] = 0.5 * double(e);
  ElementFields fields;
  fields.von_mises.assign(density.size(), 7.0);
  fields.green_strain.assign(9 * density.size(), 0.25);
  write_vtu(dir.file("f.vtu"), VtuFrame{&m, &u, &v, &fixed, &force, &density, &fields});
  const pugi::xml_document vtk = test::read_xml(dir.file("f.vtu"));
  const pugi::xml_node piece = vtk.child("VTKFile").child("UnstructuredGrid").child("Piece");
  ASSERT_TRUE(piece);
  EXPECT_EQ(piece.attribute("NumberOfPoints").value(), std::to_string(m.n_nodes()));
  EXPECT_EQ(piece.attribute("NumberOfCells").value(), std::to_string(m.n_tets()));
  // Points at rest, the displacement the vector to warp them by.
  std::vector<double> rest;
  for (const Vec3& X : m.X) rest.insert(rest.end(), {X.x, X.y, X.z});
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("Points"), "Points")), rest);
  EXPECT_STREQ(piece.child("PointData").attribute("Vectors").value(), "displacement");
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "displacement")), u);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "velocity")), v);
  EXPECT_EQ(test::decode_vtk_array<uint8_t>(test::find_array(piece.child("PointData"), "fixed")), fixed);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "contact_force")), force);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "strain_energy_density")),
            density);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "von_mises")), fields.von_mises);
  EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "green_strain")),
            fields.green_strain);
  EXPECT_STREQ(piece.child("CellData").attribute("Scalars").value(), "von_mises");
  const auto material = test::decode_vtk_array<int32_t>(test::find_array(piece.child("CellData"), "material"));
  EXPECT_EQ(material, m.region);
  // What was not computed is not written.
  for (const pugi::xml_node a : test::elements(piece.child("CellData")))
    EXPECT_STRNE(a.attribute("Name").value(), "cauchy_stress");

  write_pvd(dir.file("s.pvd"), {{0.0, "a.vtu", 0, "body"}, {0.0, "p.vtu", 1, "tip"}, {0.25, "b.vtu", 0, "body"}});
  const pugi::xml_document pvd = test::read_xml(dir.file("s.pvd"));
  const std::vector<pugi::xml_node> sets = test::elements(pvd.child("VTKFile").child("Collection"));
  ASSERT_EQ(sets.size(), 3u);
  EXPECT_STREQ(sets[2].attribute("file").value(), "b.vtu");
  EXPECT_STREQ(sets[2].attribute("timestep").value(), "0.25");
  EXPECT_STREQ(sets[1].attribute("part").value(), "1");
  EXPECT_STREQ(sets[1].attribute("name").value(), "tip");
}

// A proxy's surface: every point on the shape's surface (its signed distance
// zero), every triangle facing out, and the surface closed around the
// shape's volume (divergence theorem) to within the sampling's error.
TEST(Vtu, ProxySurfacesLieOnTheShapeFacingOut) {
  constexpr double kPi = 3.14159265358979323846;
  Pose pose;
  pose.position = Vec3(0.1, -0.2, 0.3);
  pose.orientation = glm::angleAxis(0.7, glm::normalize(Vec3(1, 1, 0)));
  struct Case {
    ProxyGeometry g;
    double volume;
  };
  const double r = 0.01, L = 0.03;
  const Vec3 h(0.02, 0.01, 0.015);
  const Case cases[] = {
      {{ProxyShape::Sphere, r, 0, Vec3(0.0)}, 4.0 / 3.0 * kPi * r * r * r},
      {{ProxyShape::Capsule, r, L, Vec3(0.0)}, 4.0 / 3.0 * kPi * r * r * r + kPi * r * r * 2 * L},
      {{ProxyShape::Box, 0.0, 0, h}, 8 * h.x * h.y * h.z},
      {{ProxyShape::Box, 0.004, 0, h},  // Minkowski sum of the box and a ball
       8 * h.x * h.y * h.z + 2 * 0.004 * 4 * (h.x * h.y + h.y * h.z + h.x * h.z) +
           kPi * 0.004 * 0.004 * 2 * (h.x + h.y + h.z) + 4.0 / 3.0 * kPi * 0.004 * 0.004 * 0.004},
  };
  for (const Case& c : cases) {
    const ProxySurface s = make_proxy_surface(c.g, pose, 1.0, 16);
    auto point = [&](int32_t k) {
      return Vec3(s.points[3 * size_t(k)], s.points[3 * size_t(k) + 1], s.points[3 * size_t(k) + 2]);
    };
    for (size_t k = 0; k < s.points.size() / 3; ++k)
      EXPECT_NEAR(locate(c.g, pose.to_local(point(int32_t(k)))).phi, 0.0, 1e-12) << to_string(c.g.shape) << " " << k;
    double volume = 0;
    for (size_t t = 0; t < s.triangles.size(); t += 3) {
      const Vec3 a = point(s.triangles[t]) - pose.position, b = point(s.triangles[t + 1]) - pose.position,
                 d = point(s.triangles[t + 2]) - pose.position;
      const Vec3 n = glm::cross(b - a, d - a);
      volume += glm::dot(a, glm::cross(b, d)) / 6.0;
      if (glm::length(n) < 1e-14) continue;  // (a box's corners gather degenerate triangles)
      const SurfacePoint at = locate(c.g, pose.to_local((a + b + d) / 3.0 + pose.position));
      EXPECT_GT(glm::dot(glm::conjugate(pose.orientation) * n, at.n), 0.0) << to_string(c.g.shape) << " " << t;
    }
    EXPECT_NEAR(volume, c.volume, 0.02 * c.volume) << to_string(c.g.shape);
  }
  // A plane: its face, a square of the given half-side, facing +y of its frame.
  ProxyGeometry plane;
  plane.shape = ProxyShape::Plane;
  const ProxySurface s = make_proxy_surface(plane, pose, 0.5);
  ASSERT_EQ(s.triangles.size(), 6u);
  for (size_t k = 0; k < 4; ++k) {
    const Vec3 q = pose.to_local(Vec3(s.points[3 * k], s.points[3 * k + 1], s.points[3 * k + 2]));
    EXPECT_NEAR(q.y, 0.0, 1e-12);
    EXPECT_NEAR(std::fabs(q.x), 0.5, 1e-12);
  }
}

}  // namespace
}  // namespace tactile

// The embedded surface (core/embedding.hpp): bound once at rest, it gives
// every rest vertex back, moves rigidly with a rigid body and affinely with an
// affine one, binds a vertex just outside to the nearest tet, and refuses one
// too far out by name; orient_surface winds closed surfaces outward.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include "core/embedding.hpp"
#include "core/quadratic.hpp"
#include "fem_fixtures.hpp"
#include "surface_fixtures.hpp"

namespace tactile {
namespace {

double signed_volume(const SurfaceMesh& s) {
  double v = 0;
  for (const Tri& t : s.triangles)
    v += glm::dot(s.vertices[size_t(t[0])], glm::cross(s.vertices[size_t(t[1])], s.vertices[size_t(t[2])]));
  return v / 6;
}

// The body: a 1 x 0.4 x 0.4 m box of 6 x 3 x 3 cells. The surface: a sphere inside it, and one poking 2 mm out
// of its top face.
struct Embedded : ::testing::Test {
  TetMesh mesh = make_box(Vec3(0, 0, 0), Vec3(1, 0.4, 0.4), {6, 3, 3});
  SurfaceMesh inside = test::make_uv_sphere(Vec3(0.5, 0.2, 0.2), 0.15, 24, 12);
  SurfaceMesh poking = test::make_uv_sphere(Vec3(0.3, 0.3, 0.2), 0.102, 16, 8);  // top at y = 0.402
};

TEST_F(Embedded, WeightsGiveEveryRestVertexBack) {
  for (const SurfaceMesh* s : {&inside, &poking}) {
    const EmbeddedSurface e = embed_surface(mesh, *s, 0.005);
    std::vector<Vec3> x(s->vertices.size());
    compute_embedded_positions(e, mesh.X, x);
    for (size_t v = 0; v < x.size(); ++v) {
      EXPECT_LT(glm::length(x[v] - s->vertices[v]), 1e-14) << v;
      const auto& w = e.weights[v];
      EXPECT_NEAR(w[0] + w[1] + w[2] + w[3], 1.0, 1e-13) << v;
      EXPECT_EQ(e.nodes[v], mesh.tets[size_t(e.tet[v])]) << v;
      if (e.outside[v] == 0) {
        for (double wi : w) EXPECT_GE(wi, -1e-12) << v;
      }
    }
  }
}

TEST_F(Embedded, ARigidMotionOfTheBodyMovesTheSurfaceRigidly) {
  const EmbeddedSurface e = embed_surface(mesh, poking, 0.005);
  const glm::dmat3 R = test::make_rotation(Vec3(1, 2, -0.5), 0.9);
  const Vec3 shift(0.3, -1.2, 2.0);
  std::vector<Vec3> x(mesh.X.size());
  for (size_t i = 0; i < x.size(); ++i) x[i] = R * mesh.X[i] + shift;
  std::vector<Vec3> y(poking.vertices.size());
  compute_embedded_positions(e, x, y);
  double outside = 0;
  for (size_t v = 0; v < y.size(); ++v) {
    EXPECT_LT(glm::length(y[v] - (R * poking.vertices[v] + shift)), 1e-13) << v;
    outside = std::max(outside, e.outside[v]);
  }
  EXPECT_GT(outside, 0.001);  // the vertices poking out went along too
}

TEST_F(Embedded, AnAffineStretchIsReproducedAndAPerTetDeformationIsFollowed) {
  const EmbeddedSurface e = embed_surface(mesh, inside, 0.005);
  const glm::dmat3 A(1.3, 0.1, 0.0, 0.2, 0.8, 0.05, 0.0, -0.1, 1.1);
  std::vector<Vec3> x(mesh.X.size());
  for (size_t i = 0; i < x.size(); ++i) x[i] = A * mesh.X[i];
  std::vector<Vec3> y(inside.vertices.size());
  compute_embedded_positions(e, x, y);
  for (size_t v = 0; v < y.size(); ++v) EXPECT_LT(glm::length(y[v] - A * inside.vertices[v]), 1e-13) << v;
  // One node moved: the vertices bound to its tets move, by its weight times its motion; no other does.
  const int32_t moved = e.nodes[0][1];
  x = mesh.X;
  x[size_t(moved)] += Vec3(0, 0.01, 0);
  compute_embedded_positions(e, x, y);
  int followed = 0;
  for (size_t v = 0; v < y.size(); ++v) {
    double w = 0;
    for (int k = 0; k < 4; ++k)
      if (e.nodes[v][size_t(k)] == moved) w = e.weights[v][size_t(k)];
    EXPECT_NEAR(y[v].y - inside.vertices[v].y, 0.01 * w, 1e-15) << v;
    followed += w != 0;
  }
  EXPECT_GT(followed, 0);
}

TEST_F(Embedded, AVertexJustOutsideBindsToTheNearestTetAndOneTooFarIsNamed) {
  const EmbeddedSurface e = embed_surface(mesh, poking, 0.005);
  // The sphere's north pole is 2 mm above the top face y = 0.4.
  EXPECT_NEAR(e.outside[0], 0.002, 1e-12);
  EXPECT_GT(mesh.X[size_t(e.nodes[0][0])].y + mesh.X[size_t(e.nodes[0][1])].y + mesh.X[size_t(e.nodes[0][2])].y +
                mesh.X[size_t(e.nodes[0][3])].y,
            0.4);  // a tet at the top
  try {
    embed_surface(mesh, poking, 0.001);
    FAIL() << "a vertex 2 mm out passed a 1 mm bound";
  } catch (const EmbeddingError& err) {
    EXPECT_NE(std::string(err.what()).find("vertex 0 at (0.3, 0.402, 0.2) is outside the body: 0.002"),
              std::string::npos)
        << err.what();
  }
  SurfaceMesh far = poking;
  far.vertices[3].x += 5;
  EXPECT_THROW(embed_surface(mesh, far, 0.005), EmbeddingError);
  SurfaceMesh bad = inside;
  bad.triangles[4][1] = int32_t(bad.vertices.size());
  EXPECT_THROW(embed_surface(mesh, bad, 0.005), EmbeddingError);
}

TEST(OrientSurface, WindsAClosedSurfaceConsistentlyAndOutward) {
  SurfaceMesh s = test::make_uv_sphere(Vec3(1, 2, 3), 0.5, 20, 10);
  const double volume = signed_volume(s);
  ASSERT_GT(volume, 0);
  // Every triangle inverted, then a random third of them back: no consistent winding left.
  std::mt19937 rng(7);
  int changed = 0;
  for (Tri& t : s.triangles) {
    std::swap(t[1], t[2]);
    if (rng() % 3 == 0)
      std::swap(t[1], t[2]);
    else
      ++changed;
  }
  EXPECT_EQ(orient_surface(s), changed);
  EXPECT_NEAR(signed_volume(s), volume, 1e-12);
  std::map<std::pair<int32_t, int32_t>, int> runs;
  for (const Tri& t : s.triangles)
    for (int k = 0; k < 3; ++k) ++runs[{t[size_t(k)], t[size_t((k + 1) % 3)]}];
  for (const auto& [edge, n] : runs) {
    EXPECT_EQ(n, 1);
    EXPECT_EQ(runs.count({edge.second, edge.first}), 1u);  // each edge run once each way
  }
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// On quadratic tets a vertex follows the linear sub-tet of its tet that holds
// it: every rest vertex comes back, weights sum to 1 and are barycentric
// (non-negative inside), its nodes are among its tet's ten; and under a
// bending field the quadratic tets carry exactly (u_y = k x^2 / 2, quadratic
// in X), each vertex lands within its sub-tet's linear interpolation error,
// k d^2 / 8 for a sub-tet d wide in x, and the surface at least twice as close
// as the linear tets carry it.
TEST_F(Embedded, OnQuadraticTetsAVertexFollowsItsSubTetWithinItsInterpolationError) {
  const TetMesh quad = make_quadratic_mesh(mesh);
  const EmbeddedSurface e = embed_surface(quad, inside, 0.005);
  const EmbeddedSurface lin = embed_surface(mesh, inside, 0.005);
  std::vector<Vec3> x(inside.vertices.size());
  compute_embedded_positions(e, quad.X, x);
  for (size_t v = 0; v < x.size(); ++v) {
    EXPECT_LT(glm::length(x[v] - inside.vertices[v]), 1e-14) << v;
    const auto& w = e.weights[v];
    EXPECT_NEAR(w[0] + w[1] + w[2] + w[3], 1.0, 1e-13) << v;
    for (double wi : w) EXPECT_GE(wi, -1e-12) << v;
    for (int32_t n : e.nodes[v]) {
      bool ours = false;
      for (int k = 0; k < 10; ++k) ours |= quad.node(size_t(e.tet[v]), k) == n;
      EXPECT_TRUE(ours) << v;
    }
  }
  const double kappa = 0.5;  // [1/m]
  auto bend = [&](const Vec3& X) { return X + Vec3(0.0, 0.5 * kappa * X.x * X.x, 0.0); };
  std::vector<Vec3> xq(quad.X.size()), xl(mesh.X.size());
  for (size_t i = 0; i < xq.size(); ++i) xq[i] = bend(quad.X[i]);
  for (size_t i = 0; i < xl.size(); ++i) xl[i] = bend(mesh.X[i]);
  std::vector<Vec3> on_quad(x.size()), on_lin(x.size());
  compute_embedded_positions(e, xq, on_quad);
  compute_embedded_positions(lin, xl, on_lin);
  double worst_quad = 0, worst_lin = 0;
  for (size_t v = 0; v < x.size(); ++v) {
    const double off = glm::length(on_quad[v] - bend(inside.vertices[v]));
    double lo = 1e9, hi = -1e9;
    for (int32_t n : e.nodes[v]) {
      lo = std::min(lo, quad.X[size_t(n)].x);
      hi = std::max(hi, quad.X[size_t(n)].x);
    }
    EXPECT_LE(off, kappa * (hi - lo) * (hi - lo) / 8 * (1 + 1e-9) + 1e-15) << v;
    worst_quad = std::max(worst_quad, off);
    worst_lin = std::max(worst_lin, glm::length(on_lin[v] - bend(inside.vertices[v])));
  }
  EXPECT_GT(worst_quad, 0.0);
  EXPECT_LT(2 * worst_quad, worst_lin);
}

}  // namespace
}  // namespace tactile

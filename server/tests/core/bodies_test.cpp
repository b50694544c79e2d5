// Scenes of several bodies in the core: add_bodies puts them into one spec,
// check_bodies refuses what cannot be one, and a model of two bodies apart
// steps each as it would alone.
#include "core/bodies.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/fem_fixtures.hpp"
#include "core/model_build.hpp"
#include "core/quadratic.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const ModelError& e) {
    return e.what();
  }
  return "";
}

const MaterialSpec kSoft{MaterialModel::NeoHookean, 1e5, 0.3, 1000};
const MaterialSpec kStiff{MaterialModel::StVK, 4e5, 0.25, 1200};

BodyParts block(const std::string& name, const Vec3& lo, const Vec3& hi, std::array<int, 3> cells,
                const MaterialSpec& material) {
  BodyParts b;
  b.name = name;
  b.mesh = make_box(lo, hi, cells);
  b.materials = {material};
  return b;
}

EssentialBc hold_below(double y) {
  EssentialBc bc;
  bc.name = "base";
  bc.where.kind = NodeSelector::Kind::Box;
  bc.where.lo = Vec3(-10, -10, -10);
  bc.where.hi = Vec3(10, y, 10);
  return bc;
}

TEST(AddBodies, MeshesFollowEachOtherAndSelectorsPickTheirBodysNodesOnly) {
  BodyParts bed = block("bed", Vec3(-0.05, 0, -0.05), Vec3(0.05, 0.02, 0.05), {4, 2, 4}, kStiff);
  bed.essential.push_back(hold_below(0.001));
  BodyParts lump = block("lump", Vec3(-0.02, 0.021, -0.02), Vec3(0.02, 0.041, 0.02), {2, 1, 2}, kSoft);
  EssentialBc held = hold_below(0.001);  // below the lump: selects none of its nodes
  held.where.kind = NodeSelector::Kind::Nodes;
  held.where.nodes = {0, 1};  // the lump's own node ids
  lump.essential.push_back(held);
  const int32_t bed_nodes = bed.mesh.n_nodes(), bed_tets = bed.mesh.n_tets();
  const TetMesh lump_mesh = lump.mesh;

  ModelSpec spec;
  add_bodies(spec, {bed, lump});
  ASSERT_EQ(spec.bodies.size(), 2u);
  EXPECT_EQ(spec.bodies[1].node_begin, bed_nodes);
  EXPECT_EQ(spec.bodies[1].tet_begin, bed_tets);
  EXPECT_EQ(spec.mesh.n_nodes(), bed_nodes + lump_mesh.n_nodes());
  for (int32_t e = 0; e < lump_mesh.n_tets(); ++e) {
    for (int k = 0; k < 4; ++k)
      EXPECT_EQ(spec.mesh.tets[size_t(bed_tets + e)][size_t(k)], lump_mesh.tets[size_t(e)][size_t(k)] + bed_nodes);
    EXPECT_EQ(spec.mesh.region_of(bed_tets + e), 1);  // the lump's material follows the bed's
  }
  ASSERT_EQ(spec.materials.size(), 2u);
  EXPECT_EQ(spec.materials[1].E, kSoft.E);
  // The bed's box would take every node below y = 1 mm of the whole spec; it takes the bed's.
  for (int32_t n : select_nodes(spec.mesh, spec.essential[0].where)) EXPECT_LT(n, bed_nodes);
  EXPECT_FALSE(select_nodes(spec.mesh, spec.essential[0].where).empty());
  EXPECT_EQ(select_nodes(spec.mesh, spec.essential[1].where), (std::vector<int32_t>{bed_nodes, bed_nodes + 1}));
  EXPECT_EQ(spec.surface, nullptr);  // neither has a fine surface
  EXPECT_EQ(check_bodies(spec).size(), 2u);
}

TEST(AddBodies, ABodyWithoutAFineSurfaceIsTouchedByItsBoundaryWhenAnotherHasOne) {
  BodyParts a = block("a", Vec3(0.0), Vec3(0.02), {2, 2, 2}, kSoft);
  BodyParts b = block("b", Vec3(0.03, 0, 0), Vec3(0.05, 0.02, 0.02), {2, 2, 2}, kSoft);
  SurfaceMesh fine;  // a's boundary, shrunk a little towards its centre
  const std::vector<Tri> faces = compute_boundary_faces(a.mesh);
  const std::vector<int32_t> nodes = compute_boundary_nodes(faces);
  std::vector<int32_t> index(a.mesh.X.size(), -1);
  for (int32_t n : nodes) {
    index[size_t(n)] = int32_t(fine.vertices.size());
    fine.vertices.push_back(Vec3(0.01) + 0.9 * (a.mesh.X[size_t(n)] - Vec3(0.01)));
  }
  for (const Tri& f : faces) fine.triangles.push_back({index[size_t(f[0])], index[size_t(f[1])], index[size_t(f[2])]});
  a.surface = std::make_shared<EmbeddedSurface>(embed_surface(a.mesh, fine, 0.0));
  ModelSpec spec;
  add_bodies(spec, {a, b});
  ASSERT_NE(spec.surface, nullptr);
  const BodySpec& sb = spec.bodies[1];
  EXPECT_EQ(spec.bodies[0].fine_vertex_end, int32_t(fine.vertices.size()));
  EXPECT_EQ(sb.fine_triangle_end - sb.fine_triangle_begin, int32_t(compute_boundary_faces(b.mesh).size()));
  // b's fine vertices are its boundary nodes, each following itself with weight 1.
  for (int32_t v = sb.fine_vertex_begin; v < sb.fine_vertex_end; ++v) {
    const Vec3 X = spec.surface->rest.vertices[size_t(v)];
    Vec3 carried(0.0);
    for (int k = 0; k < 4; ++k)
      carried +=
          spec.surface->weights[size_t(v)][size_t(k)] * spec.mesh.X[size_t(spec.surface->nodes[size_t(v)][size_t(k)])];
    EXPECT_LT(glm::length(carried - X), 1e-12);
    for (int32_t n : spec.surface->nodes[size_t(v)]) {
      EXPECT_GE(n, sb.node_begin);
      EXPECT_LT(n, sb.node_end);
    }
  }
  EXPECT_EQ(check_bodies(spec).size(), 2u);
}

TEST(AddBodies, BodiesOfTwoElementOrdersAreRefusedNamingTheBody) {
  BodyParts a = block("a", Vec3(0.0), Vec3(0.02), {1, 1, 1}, kSoft);
  BodyParts b = block("b", Vec3(0.03, 0, 0), Vec3(0.05, 0.02, 0.02), {1, 1, 1}, kSoft);
  b.mesh = make_quadratic_mesh(b.mesh);
  ModelSpec spec;
  EXPECT_EQ(error_of([&] {
              add_bodies(spec, {a, b});
            }),
            "body 1 ('b'): its element order differs from body 0's; the bodies of a scene share one");
}

TEST(CheckBodies, RefusesOverlapsSharedNodesAndTwiceUsedNamesByBody) {
  const auto spec_of = [](std::vector<BodyParts> parts) {
    ModelSpec spec;
    add_bodies(spec, std::move(parts));
    return spec;
  };
  // Touching (a face on a face) is allowed; one millimetre into the other is not.
  EXPECT_EQ(error_of([&] {
              check_bodies(spec_of({block("bed", Vec3(0.0), Vec3(0.04, 0.02, 0.04), {2, 1, 2}, kSoft),
                                    block("lump", Vec3(0.01, 0.02, 0.01), Vec3(0.03, 0.04, 0.03), {1, 1, 1}, kSoft)}));
            }),
            "");
  const std::string overlap = error_of([&] {
    check_bodies(spec_of({block("bed", Vec3(0.0), Vec3(0.04, 0.02, 0.04), {2, 1, 2}, kSoft),
                          block("lump", Vec3(0.01, 0.019, 0.01), Vec3(0.03, 0.039, 0.03), {1, 1, 1}, kSoft)}));
  });
  EXPECT_NE(overlap.find("body 0 ('bed') overlaps body 1 ('lump') at rest: its node"), std::string::npos) << overlap;
  // A body wholly inside another.
  const std::string inside = error_of([&] {
    check_bodies(spec_of({block("outer", Vec3(0.0), Vec3(0.1), {3, 3, 3}, kSoft),
                          block("inner", Vec3(0.04), Vec3(0.06), {1, 1, 1}, kSoft)}));
  });
  EXPECT_NE(inside.find("body 1 ('inner') overlaps body 0 ('outer')"), std::string::npos) << inside;

  ModelSpec twice = spec_of({block("a", Vec3(0.0), Vec3(0.02), {1, 1, 1}, kSoft),
                             block("a", Vec3(0.03, 0, 0), Vec3(0.05, 0.02, 0.02), {1, 1, 1}, kSoft)});
  EXPECT_EQ(error_of([&] { check_bodies(twice); }), "body 1 ('a'): the name is also body 0's");
  ModelSpec shared = spec_of({block("a", Vec3(0.0), Vec3(0.02), {1, 1, 1}, kSoft),
                              block("b", Vec3(0.03, 0, 0), Vec3(0.05, 0.02, 0.02), {1, 1, 1}, kSoft)});
  shared.mesh.tets.back()[0] = 0;  // a tet of b on a's node 0
  EXPECT_NE(error_of([&] { check_bodies(shared); }).find("body 1 ('b'): tet"), std::string::npos);
  ModelSpec gap = shared;
  gap.bodies[1].node_begin += 1;
  EXPECT_EQ(error_of([&] { check_bodies(gap); }),
            "body 1 ('b'): its nodes, tets and surface must follow the previous body's, and be some");
}

// Two bodies apart, each under its own load, step as each alone: the model
// of both is the two models side by side (to rounding: a node's forces are
// summed in another order).
TEST(Bodies, TwoBodiesApartStepEachAsItWouldAlone) {
  BodyParts a = block("a", Vec3(0.0), Vec3(0.06, 0.02, 0.02), {6, 2, 2}, kSoft);
  a.essential.push_back(hold_below(0.0005));
  BodyParts b = block("b", Vec3(0.1, 0, 0), Vec3(0.14, 0.03, 0.02), {4, 3, 2}, kStiff);
  NaturalLoad pull;
  pull.where.kind = NodeSelector::Kind::Box;
  pull.where.lo = Vec3(0.13, -1, -1);
  pull.where.hi = Vec3(1, 1, 1);
  pull.force = Vec3(0, 0.5, 0.2);
  b.loads.push_back(pull);
  a.loads.push_back(pull);                       // a's x never reaches 0.13: selects none of a's ...
  a.loads.back().where.lo = Vec3(0.05, -1, -1);  // ... so pull a's own end
  ModelSpec both;
  add_bodies(both, {a, b});
  both.effects.gravity = true;
  both.effects.damping = true;
  both.effects.alpha = 2.0;
  const auto alone = [&](const BodyParts& p) {
    ModelSpec s;
    add_bodies(s, {p});
    s.effects = both.effects;
    return s;
  };
  const Model<double> m_both = build_model<double>(both);
  const Model<double> m_a = build_model<double>(alone(a)), m_b = build_model<double>(alone(b));
  ASSERT_EQ(m_both.bodies.size(), 2u);
  EXPECT_EQ(m_both.bodies[1].face_end, int32_t(m_both.surface.size()));
  EXPECT_EQ(m_both.bodies[0].face_end - m_both.bodies[0].face_begin, int32_t(m_a.surface.size()));
  for (int32_t f = m_both.bodies[1].face_begin; f < m_both.bodies[1].face_end; ++f)
    for (int32_t n : m_both.surface[size_t(f)]) EXPECT_EQ(m_both.node_body[size_t(n)], 1);

  const double dt = 0.9 * std::min(m_a.dt_rest, m_b.dt_rest);
  EXPECT_EQ(m_both.dt_rest, std::min(m_a.dt_rest, m_b.dt_rest));
  Stepper<double> s_both(m_both), s_a(m_a), s_b(m_b);
  State<double> x_both = s_both.make_state(), x_a = s_a.make_state(), x_b = s_b.make_state();
  for (int k = 0; k < 400; ++k) {
    ASSERT_FALSE(s_both.step(x_both, dt));
    ASSERT_FALSE(s_a.step(x_a, dt));
    ASSERT_FALSE(s_b.step(x_b, dt));
  }
  const auto check = [&](const Model<double>& m, const State<double>& x, int32_t offset) {
    double largest = 0, worst = 0;
    for (int32_t i = 0; i < m.n_nodes; ++i) {
      const size_t alone_k = size_t(m.node_model[size_t(i)]), both_k = size_t(m_both.node_model[size_t(offset + i)]);
      for (size_t c = 0; c < 3; ++c) {
        largest = std::max(largest, std::fabs(x.u[3 * alone_k + c]));
        worst = std::max(worst, std::fabs(x.u[3 * alone_k + c] - x_both.u[3 * both_k + c]));
      }
    }
    EXPECT_GT(largest, 1e-4);  // it moved
    EXPECT_LT(worst, 1e-12 * largest + 1e-18);
  };
  check(m_a, x_a, 0);
  check(m_b, x_b, both.bodies[1].node_begin);
}

}  // namespace
}  // namespace tactile

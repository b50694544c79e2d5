// A quadratic (P2) mesh through build_model and the stepper: its nodes,
// masses and surface, selections that reach edge nodes, forces that are the
// assembled element forces in any numbering, rigid motions that store no
// energy, parts that move it as one, its guards, and its fields.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "core/fem_fixtures.hpp"
#include "core/fields.hpp"
#include "core/quadratic.hpp"

namespace tactile {
namespace {

using test::kRotationInvariantModels;
using test::make_jittered_box;
using test::make_rotation;
using test::make_spec;
using test::node_vec;
using test::OneAfterTheOther;

constexpr double kRho = 1000;

TetMesh linear_box(std::array<int, 3> cells = {3, 2, 2}) {
  return make_jittered_box(Vec3(0.0), Vec3(0.06, 0.04, 0.04), cells, 0.2);
}
TetMesh quadratic_box(std::array<int, 3> cells = {3, 2, 2}) { return make_quadratic_mesh(linear_box(cells)); }

// A bar along x held at x = 0 and pulled by `force` [N] spread over its end x = `length`.
void hold_and_load(ModelSpec& spec, double length, const Vec3& force) {
  EssentialBc held;
  held.where.kind = NodeSelector::Kind::Plane;
  held.where.normal = Vec3(1.0, 0.0, 0.0);
  NaturalLoad tip;
  tip.where = held.where;
  tip.where.point = Vec3(length, 0.0, 0.0);
  tip.force = force;
  spec.essential = {held};
  spec.loads = {tip};
}

double total_volume(const TetMesh& mesh) {
  double V = 0;
  for (const Tet& t : mesh.tets)
    V += compute_tet_volume(mesh.X[size_t(t[0])], mesh.X[size_t(t[1])], mesh.X[size_t(t[2])], mesh.X[size_t(t[3])]);
  return V;
}

// The quadratic model keeps every node of the mesh, corners and edges, each
// with a positive HRZ mass; the masses sum to rho V; its surface is the
// corners' split in four at the edge nodes, closed and wound outward (the
// divergence theorem gives the body's volume back); and its step is the
// quadratic elements' (shorter than the linear tets').
TEST(QuadraticModel, KeepsEveryNodeWithAPositiveMassAndASplitOutwardSurface) {
  const TetMesh linear = linear_box();
  const TetMesh mesh = make_quadratic_mesh(linear);
  const Model<double> model = build_model<double>(make_spec(mesh, MaterialModel::StVK));
  const Model<double> p1 = build_model<double>(make_spec(linear, MaterialModel::StVK));
  ASSERT_TRUE(model.mesh.quadratic());
  EXPECT_EQ(model.n_nodes, mesh.n_nodes());
  EXPECT_EQ(model.quadratic_blocks.size(), model.blocks.size());
  EXPECT_TRUE(p1.quadratic_blocks.empty());
  EXPECT_TRUE(std::all_of(model.m.begin(), model.m.end(), [](double m) { return m > 0; }));
  EXPECT_NEAR(model.total_mass, kRho * total_volume(mesh), 1e-12 * model.total_mass);
  EXPECT_NEAR(std::accumulate(model.m.begin(), model.m.end(), 0.0), model.total_mass, 1e-12 * model.total_mass);
  // Given and model ids translate both ways, positions with them.
  for (int32_t g = 0; g < mesh.n_nodes(); ++g) {
    ASSERT_EQ(model.node_given[size_t(model.node_model[size_t(g)])], g);
    ASSERT_EQ(model.mesh.X[size_t(model.node_model[size_t(g)])], mesh.X[size_t(g)]);
  }
  EXPECT_EQ(model.surface.size(), 4 * p1.surface.size());
  double volume = 0;  // (1/3) sum over the faces of x . n dA
  for (const Tri& t : model.surface) {
    const Vec3 &a = model.mesh.X[size_t(t[0])], &b = model.mesh.X[size_t(t[1])], &c = model.mesh.X[size_t(t[2])];
    volume += glm::dot(a, glm::cross(b - a, c - a)) / 6.0;
  }
  EXPECT_NEAR(volume, total_volume(mesh), 1e-12);
  const std::vector<int32_t> on_surface = compute_boundary_nodes(model.surface);
  EXPECT_GT(on_surface.size(), compute_boundary_nodes(p1.surface).size());
  EXPECT_LT(model.dt_rest, p1.dt_rest);
}

// A plane selects the edge nodes on it as well as the corners, and a load
// spreads over both by their (HRZ) masses.
TEST(QuadraticModel, SelectionsAndLoadsReachEdgeNodes) {
  ModelSpec spec = make_spec(quadratic_box(), MaterialModel::StVK);
  hold_and_load(spec, 0.06, Vec3(0.0, -1.0, 0.0));
  const Model<double> model = build_model<double>(spec);
  // On x = 0: the face's 3 x 3 corners and its edge nodes, 5 x 5 in all (a
  // face of 2 x 2 cells split into triangles: 16 edges, and the corners 9).
  EXPECT_EQ(model.essential[0].nodes.size(), 25u);
  EXPECT_EQ(model.loads[0].nodes.size(), 25u);
  int edge_nodes = 0;
  double weights = 0;
  for (size_t k = 0; k < model.loads[0].nodes.size(); ++k) {
    const int32_t i = model.loads[0].nodes[k];
    EXPECT_NEAR(model.mesh.X[size_t(i)].x, 0.06, 1e-12);
    if (model.node_given[size_t(i)] >= linear_box().n_nodes()) ++edge_nodes;  // given ids past the corners'
    weights += model.loads[0].weight[k];
  }
  EXPECT_EQ(edge_nodes, 16);
  EXPECT_NEAR(weights, 1.0, 1e-12);
}

// The stepper's elastic forces are the element forces of compute_p2_forces
// assembled in the mesh's own numbering, whatever the model's numbering and
// the lane layout, in both precisions; and the energy is their energy.
template <class Real>
void expect_assembled_forces(MaterialModel m, double tolerance) {
  const TetMesh mesh = quadratic_box();
  const Model<Real> model = build_model<Real>(make_spec(mesh, m));
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<Real> u(3 * size_t(mesh.n_nodes()));
  for (size_t i = 0; i < mesh.X.size(); ++i) {
    const Vec3& X = mesh.X[i];
    const Vec3 d = 0.004 * Vec3(std::sin(60 * X.y), std::cos(50 * X.x), std::sin(40 * X.z + 30 * X.x)) +
                   0.001 * Vec3(unit(rng), unit(rng), unit(rng));
    for (int k = 0; k < 3; ++k) u[3 * i + size_t(k)] = Real(d[k]);
  }
  double energy = 0;
  const std::vector<Real> f = test::compute_elastic_forces(model, u, &energy);
  std::vector<Vec3> want(mesh.X.size(), Vec3(0.0));
  double want_energy = 0, scale = 0;
  const Lame lame = compute_lame(1e5, 0.3);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    std::array<Vec3, kP2Nodes> x, fe;
    for (int a = 0; a < kP2Nodes; ++a) {
      const auto i = size_t(mesh.node(e, a));
      x[size_t(a)] = mesh.X[i] + node_vec(u, int32_t(i));
    }
    want_energy += compute_p2_forces(make_p2_element(p2_rest_nodes(mesh, e)), x, m, lame.lambda, lame.mu, &fe);
    for (int a = 0; a < kP2Nodes; ++a) want[size_t(mesh.node(e, a))] += fe[size_t(a)];
  }
  for (const Vec3& w : want) scale = std::max(scale, glm::length(w));
  ASSERT_GT(scale, 0.0);
  for (int32_t i = 0; i < mesh.n_nodes(); ++i)
    ASSERT_LE(glm::length(node_vec(f, i) - want[size_t(i)]), tolerance * scale) << to_string(m) << " node " << i;
  EXPECT_NEAR(energy, want_energy, tolerance * want_energy) << to_string(m);
}

TEST(QuadraticModel, ElasticForcesAreTheAssembledElementForces) {
  for (MaterialModel m : test::kAllModels) {
    expect_assembled_forces<double>(m, 1e-10);
    expect_assembled_forces<float>(m, 2e-4);
  }
}

// A rigid rotation and translation of a quadratic body stores no energy and
// moves no node, for every model invariant under rotation.
TEST(QuadraticModel, RigidMotionStoresNoEnergy) {
  const TetMesh mesh = quadratic_box();
  const glm::dmat3 R = make_rotation(Vec3(1.0, 2.0, -0.5), 0.9);
  for (MaterialModel m : kRotationInvariantModels) {
    const Model<double> model = build_model<double>(make_spec(mesh, m));
    double energy = -1;
    const std::vector<double> f = test::compute_elastic_forces(
        model, test::make_affine_displacement<double>(mesh, R, Vec3(0.01, -0.02, 0.03)), &energy);
    double worst = 0;
    for (double x : f) worst = std::max(worst, std::fabs(x));
    EXPECT_LT(energy, 1e-12) << to_string(m);
    EXPECT_LT(worst, 1e-8) << to_string(m) << ": " << worst << " N";  // (a stretch of 1e-3 gives ~1e-2 N here)
  }
}

// Split over parts that run in either order, a quadratic bar held at one
// end and loaded at the other moves as with one part: bit for bit between
// the orders, to round-off against one part.
TEST(QuadraticModel, PartsMoveItAsOnePartDoes) {
  ModelSpec spec =
      make_spec(make_quadratic_mesh(make_box(Vec3(0.0), Vec3(0.4, 0.05, 0.05), {96, 4, 4})), MaterialModel::NeoHookean);
  spec.integrator.threads = 2;
  hold_and_load(spec, 0.4, Vec3(0.0, -2.0, 1.0));
  const Model<double> model = build_model<double>(spec);
  ASSERT_EQ(model.parts.size(), 2u);
  using Order = OneAfterTheOther::Order;
  OneAfterTheOther forward(Order::Forward), backward(Order::Backward);
  Stepper<double> one(model), left(model, &forward), right(model, &backward);
  State<double> a = one.make_state();
  State<double> b = a, c = a;
  const double dt = 0.5 * model.dt_rest;
  for (int k = 0; k < 60; ++k) {
    ASSERT_FALSE(one.step(a, dt)) << a.fault.message;
    ASSERT_FALSE(left.step(b, dt)) << b.fault.message;
    ASSERT_FALSE(right.step(c, dt)) << c.fault.message;
  }
  double worst = 0, scale = 0;
  for (size_t j = 0; j < a.u.size(); ++j) {
    worst = std::max(worst, std::fabs(a.u[j] - b.u[j]));
    scale = std::max(scale, std::fabs(a.u[j]));
  }
  EXPECT_GT(scale, 1e-7);
  EXPECT_LE(worst, 1e-9 * scale);
  EXPECT_EQ(b.u, c.u);
  EXPECT_EQ(b.v, c.v);
}

// Free vibration of a quadratic body keeps its energy (no damping, no
// load): explicit Newmark at half the critical step neither gains nor loses
// more than its second-order error, in both precisions.
template <class Real>
void expect_energy_kept() {
  const Model<Real> model = build_model<Real>(make_spec(quadratic_box({4, 3, 3}), MaterialModel::NeoHookean));
  Stepper<Real> stepper(model);
  State<Real> s = stepper.make_state();
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3 X = model.mesh.X[size_t(i)];
    s.v[3 * size_t(i) + 1] = Real(0.3 * std::sin(50 * X.x));  // a bending mode or two
  }
  const Energy e0 = stepper.compute_energy(s);
  const double E0 = e0.kinetic + e0.elastic;
  double lo = E0, hi = E0, most_elastic = 0;
  for (int k = 0; k < 2000; ++k) {
    ASSERT_FALSE(stepper.step(s, 0.5 * model.dt_rest)) << s.fault.message;
    if (k % 50 != 49) continue;
    const Energy e = stepper.compute_energy(s);
    lo = std::min(lo, e.kinetic + e.elastic);
    hi = std::max(hi, e.kinetic + e.elastic);
    most_elastic = std::max(most_elastic, e.elastic);
  }
  EXPECT_GT(most_elastic, 0.1 * E0) << "the body must have flexed";
  EXPECT_LT((hi - lo) / E0, 0.01);
}

TEST(QuadraticModel, FreeVibrationKeepsItsEnergy) {
  expect_energy_kept<double>();
  expect_energy_kept<float>();
}

// A quadratic StVK element driven through itself faults as inverted, by id.
TEST(QuadraticModel, AnInvertedStvkElementFaultsNamingIt) {
  TetMesh linear;
  linear.X = {Vec3(0, 0, -1), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, 1)};
  linear.tets = {{0, 1, 2, 3}, {4, 1, 3, 2}};
  for (Tet& t : linear.tets)
    if (compute_tet_volume(linear.X[size_t(t[0])], linear.X[size_t(t[1])], linear.X[size_t(t[2])],
                           linear.X[size_t(t[3])]) < 0)
      std::swap(t[1], t[2]);
  const Model<double> model = build_model<double>(make_spec(make_quadratic_mesh(linear), MaterialModel::StVK));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const auto node4 = size_t(model.node_model[4]);
  s.v[3 * node4 + 2] = -200.0;  // [m/s]: node 4 through the shared face
  Fault f;
  for (int k = 0; k < 1000 && !f; ++k) f = stepper.step(s, 0.5 * model.dt_rest);
  ASSERT_EQ(f.kind, Fault::Kind::Inverted) << f.message;
  EXPECT_EQ(f.elements, std::vector<int32_t>{1});
}

// An affine displacement is a constant F, which quadratic tets reproduce
// exactly: their fields (the mean over the quadrature points) are the
// linear tets' at every tet.
TEST(QuadraticModel, FieldsOfAnAffineStretchAreTheLinearTetsFields) {
  const TetMesh linear = linear_box();
  const TetMesh mesh = make_quadratic_mesh(linear);
  const glm::dmat3 A =
      make_rotation(Vec3(0.0, 0.0, 1.0), 0.3) * glm::dmat3(1.1, 0.02, 0.0, 0.0, 0.95, 0.01, 0.0, 0.0, 1.05);
  const Model<double> q = build_model<double>(make_spec(mesh, MaterialModel::NeoHookean));
  const Model<double> p = build_model<double>(make_spec(linear, MaterialModel::NeoHookean));
  auto state = [&](const Model<double>& model, const TetMesh& given) {
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const std::vector<double> u = test::make_affine_displacement<double>(given, A, Vec3(0.0));
    for (size_t i = 0; i < model.node_model.size(); ++i)
      for (size_t d = 0; d < 3; ++d) s.u[3 * size_t(model.node_model[i]) + d] = u[3 * i + d];
    return s;
  };
  ElementFieldRequest ask;
  ask.cauchy_stress = ask.von_mises = ask.energy_density = ask.principal_stretches = true;
  const ElementFields fq = compute_element_fields(q, state(q, mesh), ask);
  const ElementFields fp = compute_element_fields(p, state(p, linear), ask);
  ASSERT_EQ(fq.von_mises.size(), fp.von_mises.size());
  for (size_t e = 0; e < fq.von_mises.size(); ++e) {
    EXPECT_NEAR(fq.von_mises[e], fp.von_mises[e], 1e-9 * fp.von_mises[e]) << e;
    EXPECT_NEAR(fq.energy_density[e], fp.energy_density[e], 1e-9 * fp.energy_density[e]) << e;
    for (size_t k = 0; k < 3; ++k)
      EXPECT_NEAR(fq.principal_stretches[3 * e + k], fp.principal_stretches[3 * e + k], 1e-12);
  }
  EXPECT_GT(fp.von_mises[0], 1e3);
}

// A quadratic mesh whose edge nodes disagree is refused, naming the tet.
TEST(QuadraticModel, MeshStructureRefusesEdgeNodesThatDisagree) {
  TetMesh mesh = quadratic_box({2, 1, 1});
  ASSERT_EQ(check_mesh_structure(mesh), "");
  TetMesh bad = mesh;
  bad.edges[1][0] = bad.edges[0][0] == bad.edges[1][0] ? bad.edges[1][1] : bad.edges[0][0];
  EXPECT_NE(check_mesh_structure(bad).find("tet 1 edge node 4"), std::string::npos) << check_mesh_structure(bad);
  bad = mesh;
  bad.edges[0][2] = mesh.tets[0][3];
  EXPECT_NE(check_mesh_structure(bad).find("a corner"), std::string::npos) << check_mesh_structure(bad);
  bad = mesh;
  bad.edges.pop_back();
  EXPECT_NE(check_mesh_structure(bad).find("edge nodes for"), std::string::npos);
  bad = mesh;
  bad.edges[0][5] = mesh.n_nodes();
  EXPECT_NE(check_mesh_structure(bad).find("outside"), std::string::npos);
  EXPECT_THROW(build_model<double>(make_spec(bad, MaterialModel::StVK)), ModelError);
}

}  // namespace
}  // namespace tactile

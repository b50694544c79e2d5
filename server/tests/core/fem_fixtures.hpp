// Shared helpers of the core tests: small meshes, specs, rotations, and the
// elastic forces and momenta of a whole model as the stepper computes them.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include "core/model.hpp"
#include "core/spec.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"

namespace tactile::test {

inline constexpr MaterialModel kAllModels[] = {MaterialModel::Linear, MaterialModel::StVK, MaterialModel::Corotational,
                                               MaterialModel::NeoHookean, MaterialModel::InvertibleStVK};
// The models invariant under rotation: the paper's claim is that these do not distort.
inline constexpr MaterialModel kRotationInvariantModels[] = {MaterialModel::StVK, MaterialModel::Corotational,
                                                             MaterialModel::NeoHookean, MaterialModel::InvertibleStVK};

// Rotation by `angle` [rad] about `axis` (any length), Rodrigues' formula (glm: column-major).
inline glm::dmat3 make_rotation(Vec3 axis, double angle) {
  axis = glm::normalize(axis);
  const double c = std::cos(angle), s = std::sin(angle);
  glm::dmat3 R(0.0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double cross = (i == j) ? 0.0 : ((j == (i + 1) % 3) ? -axis[(i + 2) % 3] : axis[(i + 1) % 3]);
      R[j][i] = (i == j ? c : 0.0) + s * cross + (1.0 - c) * axis[i] * axis[j];
    }
  return R;
}

// A regular tet of edge `edge` [m], positively oriented.
inline TetMesh make_regular_tet(double edge = 1.0) {
  TetMesh m;
  const double a = edge / std::sqrt(2.0);  // the tet inscribed in a cube of side a
  m.X = {Vec3(0, 0, 0), Vec3(a, a, 0), Vec3(a, 0, a), Vec3(0, a, a)};
  m.tets = {{0, 1, 2, 3}};
  if (compute_tet_volume(m.X[0], m.X[1], m.X[2], m.X[3]) < 0) std::swap(m.tets[0][1], m.tets[0][2]);
  return m;
}

// make_box with every interior node moved by up to `jitter` cell sizes in
// each direction (deterministic for a seed): an irregular mesh for patch tests.
inline TetMesh make_jittered_box(const Vec3& lo, const Vec3& hi, std::array<int, 3> cells, double jitter,
                                 uint32_t seed = 7) {
  TetMesh mesh = make_box(lo, hi, cells);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Vec3 h = (hi - lo) / Vec3(cells[0], cells[1], cells[2]);
  const double eps = 1e-12 * glm::length(hi - lo);
  for (Vec3& X : mesh.X) {
    const bool interior = X.x > lo.x + eps && X.x < hi.x - eps && X.y > lo.y + eps && X.y < hi.y - eps &&
                          X.z > lo.z + eps && X.z < hi.z - eps;
    if (interior) X += jitter * h * Vec3(unit(rng), unit(rng), unit(rng));
  }
  return mesh;
}

// Ids of the nodes strictly inside the bounding box of the rest mesh.
inline std::vector<int32_t> find_interior_nodes(const TetMesh& mesh) {
  const std::vector<int32_t> boundary = compute_boundary_nodes(compute_boundary_faces(mesh));
  std::vector<int32_t> out;
  size_t b = 0;
  for (int32_t i = 0; i < mesh.n_nodes(); ++i) {
    while (b < boundary.size() && boundary[b] < i) ++b;
    if (b < boundary.size() && boundary[b] == i) continue;
    out.push_back(i);
  }
  return out;
}

inline ModelSpec make_spec(TetMesh mesh, MaterialModel model, double E = 1e5, double nu = 0.3, double rho = 1000) {
  ModelSpec spec;
  spec.mesh = std::move(mesh);
  spec.materials = {MaterialSpec{model, E, nu, rho}};
  return spec;
}

// Displacement u = A X + b - X at every node (n_nodes x 3).
template <class Real>
std::vector<Real> make_affine_displacement(const TetMesh& mesh, const glm::dmat3& A, const Vec3& b) {
  std::vector<Real> u(3 * size_t(mesh.n_nodes()));
  for (size_t i = 0; i < mesh.X.size(); ++i) {
    const Vec3 d = A * mesh.X[i] + b - mesh.X[i];
    for (int k = 0; k < 3; ++k) u[3 * i + size_t(k)] = Real(d[k]);
  }
  return u;
}

// Elastic nodal forces -dU/du of the whole model at displacement u [N]
// (n_nodes x 3); `energy` receives U [J]. Both u and the forces are in the
// node numbering of the spec's mesh (the model's own, which the state uses,
// is translated through Model::node_model). Computed by the stepper itself:
// the initial acceleration at rest velocity is a = f / m (eq. 1 with lumped
// M). The model must have no BC, load, gravity or damping.
template <class Real>
std::vector<Real> compute_elastic_forces(const Model<Real>& model, const std::vector<Real>& u,
                                         double* energy = nullptr) {
  EXPECT_TRUE(model.essential.empty() && model.loads.empty() && !model.effects.gravity && !model.effects.damping);
  Stepper<Real> stepper(model);
  State<Real> s = stepper.make_state();
  for (size_t i = 0; i < model.node_model.size(); ++i)
    for (size_t d = 0; d < 3; ++d) s.u[3 * size_t(model.node_model[i]) + d] = u[3 * i + d];
  stepper.apply_initial_acceleration(s);
  std::vector<Real> f(s.a.size());
  for (size_t i = 0; i < model.node_model.size(); ++i) {
    const auto k = size_t(model.node_model[i]);
    for (size_t d = 0; d < 3; ++d) f[3 * i + d] = s.a[3 * k + d] * model.m[k];
  }
  if (energy) *energy = stepper.compute_energy(s).elastic;
  return f;
}

inline Vec3 node_vec(const std::vector<double>& a, int32_t i) {
  return {a[3 * size_t(i)], a[3 * size_t(i) + 1], a[3 * size_t(i) + 2]};
}
inline Vec3 node_vec(const std::vector<float>& a, int32_t i) {
  return {double(a[3 * size_t(i)]), double(a[3 * size_t(i) + 1]), double(a[3 * size_t(i) + 2])};
}

// Linear momentum sum m v [kg m/s] and angular momentum about the origin sum m x cross v [kg m^2/s].
template <class Real>
void compute_momenta(const Model<Real>& model, const State<Real>& s, Vec3* p, Vec3* L) {
  *p = Vec3(0.0);
  *L = Vec3(0.0);
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const double m = double(model.m[size_t(i)]);
    const Vec3 v = node_vec(s.v, i);
    const Vec3 x = model.mesh.X[size_t(i)] + node_vec(s.u, i);
    *p += m * v;
    *L += m * glm::cross(x, v);
  }
}

// Runs a pass's parts one after another on the calling thread, first to
// last, last to first, or in turns each way, while telling the stepper it
// has two workers: the part that runs first claims all of its pair's middle
// chunks, from its own end, and the other finds none left.
class OneAfterTheOther final : public ParallelFor {
 public:
  enum class Order { Forward, Backward, InTurns };
  explicit OneAfterTheOther(Order order) : order_(order) {}
  int32_t workers() const override { return 2; }
  void run(int32_t n, void (*fn)(void* ctx, int32_t i), void* ctx) override {
    const bool backwards = order_ == Order::Backward || (order_ == Order::InTurns && turn_);
    for (int32_t k = 0; k < n; ++k) fn(ctx, backwards ? n - 1 - k : k);
    turn_ = !turn_;
  }

 private:
  Order order_;
  bool turn_ = false;
};

}  // namespace tactile::test

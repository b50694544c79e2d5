// Physical laws and benchmark problems on whole models: rigid motion, the
// patch test, a spinning body, a cantilever against beam theory, and the
// paper's Fig. 2 (a column twisted by a rigid lid).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "core/fem_fixtures.hpp"
#include "core/model.hpp"
#include "core/stepper.hpp"
#include "study/beam_theory.hpp"

namespace tactile {
namespace {

using test::compute_elastic_forces;
using test::kAllModels;
using test::make_affine_displacement;
using test::make_jittered_box;
using test::make_rotation;
using test::make_spec;
using test::node_vec;

constexpr double kE = 1e5;  // [Pa]

double max_norm(const std::vector<double>& f, const std::vector<int32_t>* nodes = nullptr) {
  double worst = 0;
  if (nodes) {
    for (int32_t i : *nodes) worst = std::max(worst, glm::length(node_vec(f, i)));
  } else {
    for (size_t i = 0; i < f.size() / 3; ++i) worst = std::max(worst, glm::length(node_vec(f, int32_t(i))));
  }
  return worst;
}

// Sum of the deformed tet volumes [m^3].
template <class Real>
double compute_deformed_volume(const TetMesh& mesh, const std::vector<Real>& u) {
  double V = 0;
  for (const Tet& t : mesh.tets) {
    Vec3 x[4];
    for (size_t c = 0; c < 4; ++c) x[c] = mesh.X[size_t(t[c])] + node_vec(u, t[c]);
    V += compute_tet_volume(x[0], x[1], x[2], x[3]);
  }
  return V;
}

// ---- rigid motion -------------------------------------------------------------

// The paper's central claim (section 3) on a whole irregular mesh: a rigid
// rotation (90, 180, 270 degrees about skew axes) plus a translation stores
// no energy and gives no force with the Green strain (eqs. 5-6) and the other
// rotation-invariant models, to round-off; the small strain (eqs. 2-3) sees
// it as a deformation.
template <class Real>
void check_rigid_motion(double tol) {
  const TetMesh mesh = make_jittered_box(Vec3(0.0), Vec3(1.0), {3, 3, 3}, 0.2);
  const double h = 1.0 / 3;
  const Vec3 axes[] = {Vec3(1, 2, 3), Vec3(-2, 0.5, 1)};
  for (const Vec3& axis : axes) {
    for (double deg : {90.0, 180.0, 270.0}) {
      const glm::dmat3 R = make_rotation(axis, deg * std::numbers::pi / 180);
      const std::vector<Real> u = make_affine_displacement<Real>(mesh, R, Vec3(0.3, -2.0, 5.0));
      for (MaterialModel m : kAllModels) {
        const Model<Real> model = build_model<Real>(make_spec(mesh, m, kE));
        double U = 0;
        const std::vector<Real> f = compute_elastic_forces(model, u, &U);
        std::vector<double> fd(f.begin(), f.end());
        if (m == MaterialModel::Linear) {
          EXPECT_GT(max_norm(fd), 0.05 * kE * h * h) << deg << " deg";
          EXPECT_GT(U, 0.05 * kE) << deg << " deg";
        } else {
          EXPECT_LT(max_norm(fd), tol * kE * h * h) << to_string(m) << " " << deg << " deg";
          EXPECT_LT(std::fabs(U), tol * kE) << to_string(m) << " " << deg << " deg";
        }
      }
    }
  }
}

TEST(RigidMotion, GivesNoForceExceptForLinearStrain) {
  check_rigid_motion<double>(1e-11);
  check_rigid_motion<float>(1e-4);  // F is formed from displacements of ~3 m in float
}

// A body spinning freely: the linear model has no force against an
// infinitesimal rotation, so the body drifts along the tangent of its
// rotation and grows (the paper's Fig. 3 distortion); the rotation-invariant
// models spin it rigidly, keeping their volume (stiff enough here, E = 1e7 Pa,
// for the centrifugal stretch to stay under 0.1 %).
TEST(RigidMotion, SpinningBodyGrowsOnlyWithLinearStrain) {
  const TetMesh mesh = make_jittered_box(Vec3(0.0), Vec3(1.0), {3, 3, 3}, 0.2);
  const double V0 = compute_deformed_volume(mesh, std::vector<double>(3 * mesh.X.size(), 0.0));
  for (MaterialModel m : kAllModels) {
    const Model<double> model = build_model<double>(make_spec(mesh, m, 1e7));
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const Vec3 omega(0.0, 5.0, 0.0), c(0.5);  // [rad/s]: 1 rad in 0.2 s
    for (int32_t i = 0; i < model.n_nodes; ++i) {
      const Vec3 v = glm::cross(omega, model.mesh.X[size_t(i)] - c);
      for (int d = 0; d < 3; ++d) s.v[3 * size_t(i) + size_t(d)] = v[d];
    }
    while (s.t < 0.2) ASSERT_FALSE(stepper.step(s, 0.5 * model.dt_rest)) << to_string(m);
    const double growth = compute_deformed_volume(model.mesh, s.u) / V0 - 1;
    if (m == MaterialModel::Linear) {
      EXPECT_GT(growth, 0.5) << "linear";  // (1 + theta^2) in the plane of rotation
    } else {
      EXPECT_LT(std::fabs(growth), 0.002) << to_string(m);
    }
  }
}

// ---- patch test ---------------------------------------------------------------

// A homogeneous deformation x = A X + b on an irregular mesh: the stress is
// the same in every element, so each interior node's forces cancel and each
// boundary node carries exactly its share of the traction, -P N dA / 3 from
// each boundary triangle it is a corner of. Every model, any A.
TEST(PatchTest, HomogeneousDeformationGivesTheExactNodalForces) {
  const TetMesh mesh = make_jittered_box(Vec3(0.0), Vec3(1.0), {4, 4, 4}, 0.25);
  const std::vector<int32_t> interior = test::find_interior_nodes(mesh);
  ASSERT_EQ(interior.size(), 27u);
  const std::vector<Tri> faces = compute_boundary_faces(mesh);
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> unit(-0.2, 0.2);
  for (MaterialModel m : kAllModels) {
    const Model<double> model = build_model<double>(make_spec(mesh, m, kE));
    for (int trial = 0; trial < 3; ++trial) {
      glm::dmat3 A = make_rotation(Vec3(1, -1, 2), 0.7 * trial);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) A[j][i] += unit(rng);
      const std::vector<double> u = make_affine_displacement<double>(mesh, A, Vec3(0.1, 0.2, -0.3));
      const std::vector<double> f = compute_elastic_forces(model, u);
      double F[9], P[9] = {};  // row-major
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) F[3 * i + j] = A[j][i];
      const Lame l = compute_lame(kE, 0.3);
      material::stress(m, F, l.lambda, l.mu, P);
      std::vector<double> expected(f.size(), 0.0);
      for (const Tri& t : faces) {
        const Vec3 nA =
            0.5 * glm::cross(mesh.X[size_t(t[1])] - mesh.X[size_t(t[0])], mesh.X[size_t(t[2])] - mesh.X[size_t(t[0])]);
        for (int i = 0; i < 3; ++i) {
          const double traction = P[3 * i] * nA.x + P[3 * i + 1] * nA.y + P[3 * i + 2] * nA.z;
          for (int32_t node : t) expected[3 * size_t(node) + size_t(i)] -= traction / 3;
        }
      }
      double scale = 0;
      for (double x : expected) scale = std::max(scale, std::fabs(x));
      ASSERT_GT(scale, 1e-3 * kE / 16) << "the deformation should load the boundary";
      EXPECT_LT(max_norm(f, &interior), 1e-10 * scale) << to_string(m) << " trial " << trial;
      double worst = 0;
      for (size_t k = 0; k < f.size(); ++k) worst = std::max(worst, std::fabs(f[k] - expected[k]));
      EXPECT_LT(worst, 1e-10 * scale) << to_string(m) << " trial " << trial;
    }
  }
}

// The patch test's other half: with the boundary held at a linear
// displacement field, damped dynamics comes to rest on that same field
// inside (the linear model reproduces linear fields exactly).
TEST(PatchTest, DampedDynamicsReproducesALinearField) {
  const TetMesh mesh = make_jittered_box(Vec3(0.0), Vec3(1.0), {4, 4, 4}, 0.25);
  const glm::dmat3 G(1e-3, 2e-3, -1e-3, 0.5e-3, -2e-3, 1e-3, 3e-3, 0.0, 1e-3);  // displacement gradient
  const Vec3 b(1e-3, -2e-3, 0.5e-3);
  auto field = [&](const Vec3& X) { return G * X + b; };
  ModelSpec spec = make_spec(mesh, MaterialModel::Linear, kE);
  const std::vector<int32_t> boundary = compute_boundary_nodes(compute_boundary_faces(mesh));
  for (int32_t i : boundary) {  // each boundary node shifted to the field, from before t = 0 on
    EssentialBc bc;
    bc.where.kind = NodeSelector::Kind::Nodes;
    bc.where.nodes = {i};
    bc.direction = field(mesh.X[size_t(i)]);
    bc.shift = MotionProfile{MotionProfile::Kind::Ramp, -1.0, 0.0, 1.0, 0.0};
    spec.essential.push_back(bc);
  }
  // Damped near critically for the slowest mode (a fixed unit cube, c_s pi sqrt(3)).
  const Lame l = compute_lame(kE, 0.3);
  spec.effects.damping = true;
  spec.effects.alpha = 2 * std::numbers::pi * std::sqrt(3.0) * std::sqrt(l.mu / 1000);
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  // The state in the model's node numbering, node i of the mesh as node_model[i].
  const TetMesh& at = model.mesh;
  for (int32_t i : boundary)  // start where the BCs hold the boundary; the inside at rest
    for (int d = 0; d < 3; ++d) s.u[3 * size_t(model.node_model[size_t(i)]) + size_t(d)] = field(mesh.X[size_t(i)])[d];
  while (s.t < 2.0) {
    const AdvanceReport r = stepper.advance(s, 0.05);
    ASSERT_FALSE(r.fault) << r.fault.message;
  }
  double worst = 0;
  for (int32_t i : test::find_interior_nodes(at))
    worst = std::max(worst, glm::length(node_vec(s.u, i) - field(at.X[size_t(i)])));
  EXPECT_LT(worst, 1e-9);  // of a field of ~3e-3 m
  for (int32_t i : boundary) {
    const int32_t k = model.node_model[size_t(i)];
    EXPECT_LT(glm::length(node_vec(s.u, k) - field(at.X[size_t(k)])), 1e-15);
  }
}

// ---- cantilever against beam theory -------------------------------------------

// A cantilever of length L along x, square section h = L / 10, clamped at
// x = 0 and loaded at x = L by a shear force P spread over the end nodes
// (natural load): its tip deflection and first frequency against the closed
// forms of study/beam_theory.hpp (Timoshenko, Euler-Bernoulli).
struct Beam : CantileverTheory {
  // n cells through the thickness, 10 n along; the centred split bends better than Kuhn's.
  TetMesh mesh(int n) const { return make_box(Vec3(0.0), Vec3(L, h, h), {10 * n, n, n}, BoxSplit::centred24); }
  ModelSpec spec(int n) const {
    ModelSpec s = make_spec(mesh(n), MaterialModel::StVK, E, nu, rho);
    s.integrator.precision = Precision::Float;
    EssentialBc clamp;
    clamp.name = "clamp";
    clamp.where.kind = NodeSelector::Kind::Plane;
    clamp.where.normal = Vec3(1, 0, 0);
    clamp.where.point = Vec3(0.0);
    s.essential = {clamp};
    return s;
  }
};

// Mass-weighted mean y displacement of the nodes on the plane x = L [m].
double compute_tip_deflection(const Model<float>& model, const std::vector<float>& u, double L) {
  double d = 0, m = 0;
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    if (std::fabs(model.mesh.X[size_t(i)].x - L) > 1e-9 * L) continue;
    d += double(model.m[size_t(i)]) * double(u[3 * size_t(i) + 1]);
    m += double(model.m[size_t(i)]);
  }
  return d / m;
}

// Static deflection under a tip load P by damped dynamics: alpha = 2 omega_1
// is critical for the first mode, whose error then falls as
// (1 + w t) exp(-w t), 5e-4 at w t = 10.
double solve_cantilever(const Beam& beam, int n, double P) {
  ModelSpec spec = beam.spec(n);
  NaturalLoad load;
  load.name = "tip";
  load.where.kind = NodeSelector::Kind::Plane;
  load.where.normal = Vec3(1, 0, 0);
  load.where.point = Vec3(beam.L, 0, 0);
  load.force = Vec3(0, -P, 0);
  spec.loads = {load};
  spec.effects.damping = true;
  spec.effects.alpha = 2 * beam.omega1();
  spec.integrator.safety = 1.0;  // the estimate is a bound (critical-step tests)
  const Model<float> model = build_model<float>(spec);
  Stepper<float> stepper(model);
  State<float> s = stepper.make_state();
  while (s.t < 10 / beam.omega1()) {
    const AdvanceReport r = stepper.advance(s, 0.05 / beam.omega1());
    EXPECT_FALSE(r.fault) << r.fault.message;
    if (r.fault) return 0;
  }
  return -compute_tip_deflection(model, s.u, beam.L);
}

TEST(Cantilever, TipDeflectionConvergesToTimoshenko) {
  const Beam beam;
  const double P = 3 * beam.E * beam.I() * 1e-3 / (beam.L * beam.L);  // tip deflection ~ L / 1000: linear range
  const double reference = beam.deflection(P);
  double previous = INFINITY;
  for (int n : {2, 3, 4, 6}) {
    const double error = solve_cantilever(beam, n, P) / reference - 1;
    std::printf("[ beam    ] %d x %d x %d cells (%d tets): tip deflection error %+.2f %%\n", 10 * n, n, n,
                24 * 10 * n * n * n, 100 * error);
    EXPECT_LT(std::fabs(error), previous) << n;  // falls with h
    previous = std::fabs(error);
  }
  EXPECT_LT(previous, 0.03);  // finest mesh within 3 %
}

// Free vibration from the first Euler-Bernoulli mode shape (w(x) with the
// cross-sections turned by w'(x)), undamped; the period from the zero
// crossings of the tip deflection.
double measure_first_frequency(const Beam& beam, int n) {
  const Model<float> model = build_model<float>(beam.spec(n));
  Stepper<float> stepper(model);
  State<float> s = stepper.make_state();
  const double bL = 1.8751040687, sigma = (std::cosh(bL) + std::cos(bL)) / (std::sinh(bL) + std::sin(bL));
  const double k = bL / beam.L;
  auto w = [&](double x) { return std::cosh(k * x) - std::cos(k * x) - sigma * (std::sinh(k * x) - std::sin(k * x)); };
  auto dw = [&](double x) {
    return k * (std::sinh(k * x) + std::sin(k * x) - sigma * (std::cosh(k * x) - std::cos(k * x)));
  };
  const double amplitude = 1e-3 * beam.L / w(beam.L);
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3& X = model.mesh.X[size_t(i)];
    s.u[3 * size_t(i)] = float(-amplitude * (X.y - beam.h / 2) * dw(X.x));
    s.u[3 * size_t(i) + 1] = float(amplitude * w(X.x));
  }
  const double dt = 0.9 * model.dt_rest;
  std::vector<double> crossings;
  double previous = compute_tip_deflection(model, s.u, beam.L);
  while (s.t < 2.3 / beam.f1()) {
    const double t0 = s.t;
    const Fault f = stepper.step(s, dt);
    EXPECT_FALSE(f) << f.message;
    if (f) return 0;
    const double d = compute_tip_deflection(model, s.u, beam.L);
    if ((previous > 0) != (d > 0)) crossings.push_back(t0 + dt * previous / (previous - d));  // linear interpolation
    previous = d;
  }
  EXPECT_GE(crossings.size(), 4u);
  if (crossings.size() < 2) return 0;
  const double period = 2 * (crossings.back() - crossings.front()) / double(crossings.size() - 1);
  return 1 / period;
}

TEST(Cantilever, FirstFrequencyConvergesToEulerBernoulli) {
  const Beam beam;
  double previous = INFINITY;
  for (int n : {2, 4}) {
    const double error = measure_first_frequency(beam, n) / beam.f1() - 1;
    std::printf("[ beam    ] %d x %d x %d cells: first frequency error %+.2f %% (Euler-Bernoulli %.4f Hz)\n", 10 * n, n,
                n, 100 * error, beam.f1());
    EXPECT_LT(std::fabs(error), previous) << n;
    previous = std::fabs(error);
  }
  EXPECT_LT(previous, 0.03);
}

// ---- Fig. 2: a twisted column -------------------------------------------------

// Area [m^2] of the deformed section through the nodes that lie on the rest
// plane y = y0 at the boundary of a structured box column: the perimeter of
// its grid, in order (the vector area, so a warped polygon counts its projection).
double compute_section_area(const Model<double>& model, const State<double>& s, std::array<int, 3> cells, int j) {
  const int nx = cells[0], ny = cells[1], nz = cells[2];
  // make_box numbers node (i, j, k) i + (nx + 1) (j + (ny + 1) k); the model renumbers it.
  auto grid = [&](int i, int k) { return model.node_model[size_t(i + (nx + 1) * (j + (ny + 1) * k))]; };
  std::vector<int32_t> ring;
  for (int i = 0; i < nx; ++i) ring.push_back(grid(i, 0));
  for (int k = 0; k < nz; ++k) ring.push_back(grid(nx, k));
  for (int i = nx; i > 0; --i) ring.push_back(grid(i, nz));
  for (int k = nz; k > 0; --k) ring.push_back(grid(0, k));
  Vec3 area(0.0);
  for (size_t a = 0; a < ring.size(); ++a) {
    const int32_t p = ring[a], q = ring[(a + 1) % ring.size()];
    area += 0.5 * glm::cross(model.mesh.X[size_t(p)] + node_vec(s.u, p), model.mesh.X[size_t(q)] + node_vec(s.u, q));
  }
  return glm::length(area);
}

// The column of Fig. 2: three times as tall as wide, bottom fixed, top turned
// 90 degrees about the vertical axis as a rigid lid, slowly, then held until
// it rests. Returns the mid-height section's area over its rest area.
double twist_column(MaterialModel m) {
  const double w = 0.1, H = 3 * w;
  const std::array<int, 3> cells{6, 18, 6};
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(w, H, w), cells), m, kE, 0.3, 1000);
  EssentialBc base;
  base.name = "base";
  base.where.kind = NodeSelector::Kind::Plane;
  base.where.point = Vec3(0.0);
  EssentialBc lid;
  lid.name = "lid";
  lid.where.kind = NodeSelector::Kind::Plane;
  lid.where.point = Vec3(0.0, H, 0.0);
  lid.centre = Vec3(w / 2, H, w / 2);
  lid.axis = Vec3(0, 1, 0);
  lid.angle = MotionProfile{MotionProfile::Kind::Ramp, 0.0, 0.5, std::numbers::pi / 2, 0.0};
  spec.essential = {base, lid};
  // Damped near critically for the first torsion mode (~30 rad/s).
  spec.effects.damping = true;
  spec.effects.alpha = 60;
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double rest = compute_section_area(model, s, cells, cells[1] / 2);
  EXPECT_NEAR(rest, w * w, 1e-15);
  while (s.t < 1.5) {
    const AdvanceReport r = stepper.advance(s, 0.01);
    EXPECT_FALSE(r.fault) << to_string(m) << ": " << r.fault.message;
    if (r.fault) break;
  }
  EXPECT_LT(s.energy.latest.kinetic, 1e-6 * s.energy.latest.elastic) << to_string(m) << ": not at rest";
  return compute_section_area(model, s, cells, cells[1] / 2) / rest;
}

// With the Green strain (the paper's StVK) and Neo-Hookean the section keeps
// its area within 5 % (what it loses is the physical Poisson contraction of
// fibres stretched into helices); with the small strain it swells (the
// paper: "grown bigger"). Corotational is left out for run time only (its
// kernel costs ~50x StVK's); the rigid-motion tests cover its invariance.
TEST(Fig2, TwistedColumnKeepsItsSectionWithGreenStrainOnly) {
  for (MaterialModel m : {MaterialModel::StVK, MaterialModel::NeoHookean, MaterialModel::Linear}) {
    const double ratio = twist_column(m);
    std::printf("[ fig. 2  ] %-12s mid-height section area / rest area: %.4f\n", std::string(to_string(m)).c_str(),
                ratio);
    if (m == MaterialModel::Linear) {
      EXPECT_GT(std::fabs(ratio - 1.0), 0.25);
    } else {
      EXPECT_NEAR(ratio, 1.0, 0.05) << to_string(m);
    }
  }
}

}  // namespace
}  // namespace tactile

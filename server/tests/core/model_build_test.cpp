// The stages of build_model (core/model_build.hpp), each on data written
// inline: one test per stage, against what the stage promises. The model
// they make together is tested in model_test.cpp.
#include "core/model_build.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "core/fem_fixtures.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

using test::make_regular_tet;

// The ModelError `f` throws, or "" when it throws none.
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const ModelError& e) {
    return e.what();
  }
  return "";
}

const std::vector<MaterialSpec> kSoft{MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000}};

// Two tets sharing the face (0, 1, 2), and a node (5) in neither.
TetMesh two_tets_and_a_stray_node() {
  TetMesh m;
  m.X = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3(5, 5, 5)};
  m.tets = {{0, 1, 2, 3}, {0, 2, 1, 4}};
  return m;
}

TEST(CheckMaterials, NamesTheMaterialAndFieldOutOfRange) {
  std::vector<MaterialSpec> m = {kSoft[0], kSoft[0]};
  EXPECT_EQ(error_of([&] { check_materials(m); }), "");
  m[1].nu = 0.5;
  EXPECT_EQ(error_of([&] { check_materials(m); }), "materials[1].nu must lie in (-1, 0.5), got 0.500000");
  m[1] = kSoft[0];
  m[1].E = std::nan("");
  EXPECT_NE(error_of([&] { check_materials(m); }).find("materials[1].E must be > 0 Pa"), std::string::npos);
  m[1] = kSoft[0];
  m[1].rho = -1;
  EXPECT_NE(error_of([&] { check_materials(m); }).find("materials[1].rho must be > 0"), std::string::npos);
}

TEST(ComputeElementConstants, ARegularTetsVolumeAltitudeLameAndStep) {
  const double a = 0.01;
  const TetMesh mesh = make_regular_tet(a);
  const ElementConstants c = compute_element_constants(mesh, kSoft);
  ASSERT_EQ(c.volume.size(), 1u);
  EXPECT_NEAR(c.volume[0], a * a * a / (6 * std::sqrt(2.0)), 1e-15);
  EXPECT_NEAR(c.altitude[0], a * std::sqrt(2.0 / 3.0), 1e-15);
  const Lame lame = compute_lame(1e5, 0.3);
  EXPECT_EQ(c.lambda[0], lame.lambda);
  EXPECT_EQ(c.mu[0], lame.mu);
  EXPECT_EQ(c.model[0], MaterialModel::StVK);
  EXPECT_EQ(c.dt[0],
            compute_element_critical_dt(mesh.X[0], mesh.X[1], mesh.X[2], mesh.X[3], lame.lambda, lame.mu, 1000));
  EXPECT_TRUE(c.any_non_invertible) << "plain StVK cannot invert";
  const ElementConstants n = compute_element_constants(mesh, {MaterialSpec{MaterialModel::NeoHookean, 1e5, 0.3, 1000}});
  EXPECT_FALSE(n.any_non_invertible);
}

TEST(ComputeElementConstants, AQuadraticMeshTakesEachTetsQuadraticStep) {
  const TetMesh mesh = test::make_jittered_box(Vec3(0.0), Vec3(0.06, 0.04, 0.02), {3, 2, 1}, 0.2);
  const TetMesh nodes = make_quadratic_mesh(mesh);
  const ElementConstants linear = compute_element_constants(mesh, kSoft);
  const ElementConstants quadratic = compute_element_constants(nodes, kSoft);
  const Lame lame = compute_lame(1e5, 0.3);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    std::array<Vec3, kP2Nodes> X;
    for (int a = 0; a < 4; ++a) X[size_t(a)] = mesh.X[size_t(mesh.tets[e][size_t(a)])];
    for (int k = 0; k < 6; ++k) X[size_t(4 + k)] = nodes.X[size_t(nodes.edges[e][size_t(k)])];
    EXPECT_EQ(quadratic.dt[e], compute_p2_critical_dt(X, lame.lambda, lame.mu, 1000)) << e;
    EXPECT_LT(quadratic.dt[e], linear.dt[e]) << e;
    EXPECT_EQ(quadratic.volume[e], linear.volume[e]) << e;
  }
}

TEST(ComputeElementConstants, RefusesInvertedTetsAndRegionsWithoutAMaterialByName) {
  TetMesh mesh = two_tets_and_a_stray_node();
  std::swap(mesh.tets[1][1], mesh.tets[1][2]);
  EXPECT_EQ(error_of([&] { compute_element_constants(mesh, kSoft); }), "mesh refused: 1 inverted tet(s) (ids 1)");
  mesh = two_tets_and_a_stray_node();
  mesh.region = {0, 3};
  EXPECT_EQ(error_of([&] { compute_element_constants(mesh, kSoft); }),
            "tet 1 is in region 3 but materials has 1 entries");
}

TEST(ComputeLumpedMasses, EachTetGivesAQuarterOfItsMassToEachCornerAndAStrayNodeIsRefused) {
  TetMesh mesh = two_tets_and_a_stray_node();
  EXPECT_EQ(error_of([&] {
              compute_lumped_masses(mesh, kSoft, {1.0 / 6, 1.0 / 6});
            }),
            "mesh has 1 node(s) in no tet (ids 5); compact the mesh first");
  mesh.X.pop_back();
  const std::vector<double> m = compute_lumped_masses(mesh, kSoft, {1.0 / 6, 1.0 / 6});
  const double q = 1000.0 / 6 / 4;
  EXPECT_EQ(m, (std::vector<double>{2 * q, 2 * q, 2 * q, q, q}));
  EXPECT_NEAR(std::accumulate(m.begin(), m.end(), 0.0), 1000.0 / 3, 1e-12);
}

// A regular tet and a flat one (its apex 5 % of the way up) sharing a face:
// the flat one's step is the shorter.
TetMesh a_tet_and_a_sliver() {
  TetMesh m;
  m.X = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(0.3, 0.3, -0.05)};
  m.tets = {{0, 1, 2, 3}, {0, 2, 1, 4}};
  return m;
}

TEST(ScaleElementMasses, TheTetsUnderTheTargetAreMadeDenserToReachItAndNoOthers) {
  TetMesh mesh = a_tet_and_a_sliver();
  ElementConstants c = compute_element_constants(mesh, kSoft);
  const ElementConstants before = c;
  ASSERT_LT(c.dt[1], c.dt[0]);
  EXPECT_EQ(scale_element_masses(c, 0.0), (std::vector<double>{1.0, 1.0})) << "none asked for";
  EXPECT_EQ(c.dt, before.dt);
  const double target = std::sqrt(c.dt[0] * c.dt[1]);  // between the two
  const std::vector<double> scale = scale_element_masses(c, target);
  EXPECT_EQ(scale[0], 1.0);
  EXPECT_NEAR(scale[1], (target / before.dt[1]) * (target / before.dt[1]), 1e-12 * scale[1]);
  EXPECT_EQ(c.dt[0], before.dt[0]);
  EXPECT_EQ(c.dt[1], target);
  // The step it reports is the one the denser material has: a step goes as
  // the square root of the density.
  mesh.region = {0, 1};
  MaterialSpec denser = kSoft[0];
  denser.rho *= scale[1];
  const ElementConstants dense = compute_element_constants(mesh, {kSoft[0], denser});
  EXPECT_NEAR(dense.dt[1], target, 1e-12 * target);
  // And the nodes of the sliver carry its added mass, a quarter each.
  const std::vector<double> plain = compute_lumped_masses(mesh, {kSoft[0], kSoft[0]}, c.volume);
  const std::vector<double> heavy = compute_lumped_masses(mesh, {kSoft[0], kSoft[0]}, c.volume, scale);
  EXPECT_EQ(heavy, compute_lumped_masses(mesh, {kSoft[0], denser}, c.volume));
  const double added = (scale[1] - 1.0) * kSoft[0].rho * c.volume[1];
  EXPECT_NEAR(heavy[4] - plain[4], added / 4, 1e-12 * heavy[4]);
  EXPECT_EQ(heavy[3], plain[3]) << "a node of the regular tet alone";
}

TEST(ComputeElementOrder, APermutationInPartsOfWholeSlabsGroupedByMaterial) {
  TetMesh mesh = make_box(Vec3(0.0), Vec3(0.3, 0.1, 0.1), {30, 8, 8});  // 11 520 tets, longest along x
  mesh.region.resize(mesh.tets.size());
  for (size_t e = 0; e < mesh.tets.size(); ++e) mesh.region[e] = int32_t(e % 3 == 0);
  const ElementConstants c = compute_element_constants(mesh, {kSoft[0], kSoft[0]});
  EXPECT_EQ(compute_element_order(mesh, c.volume, 1).n_parts, 1);
  EXPECT_EQ(compute_element_order(mesh, c.volume, 8).n_parts, 2) << "4096 tets a part at least";
  const ElementOrder o = compute_element_order(mesh, c.volume, 2);
  ASSERT_EQ(o.n_parts, 2);
  std::vector<int32_t> sorted = o.order;
  std::sort(sorted.begin(), sorted.end());
  for (size_t k = 0; k < sorted.size(); ++k) ASSERT_EQ(sorted[k], int32_t(k));
  auto centre_x = [&](int32_t e) {
    double x = 0;
    for (int32_t n : mesh.tets[size_t(e)]) x += mesh.X[size_t(n)].x / 4;
    return x;
  };
  double last_x_of_part0 = -1, first_x_of_part1 = 1e9;
  for (size_t k = 1; k < o.order.size(); ++k) {
    const int32_t a = o.order[k - 1], b = o.order[k];
    const int32_t pa = o.part_of[size_t(a)], pb = o.part_of[size_t(b)];
    ASSERT_LE(pa, pb) << "parts in order";
    if (pa == pb) {
      ASSERT_LE(mesh.region_of(a), mesh.region_of(b)) << "one run per material within a part";
    }
  }
  for (int32_t e : o.order) {
    if (o.part_of[size_t(e)] == 0) last_x_of_part0 = std::max(last_x_of_part0, centre_x(e));
    if (o.part_of[size_t(e)] == 1) first_x_of_part1 = std::min(first_x_of_part1, centre_x(e));
  }
  EXPECT_LT(last_x_of_part0, first_x_of_part1 + 0.011) << "parts are slabs across the longest axis";
}

template <class Real>
void check_lane_blocks() {
  constexpr int W = kLanes<Real>;
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(0.1, 0.05, 0.05), {5, 3, 3});  // 270 tets: padding in the last block
  const ElementConstants c = compute_element_constants(mesh, kSoft);
  const ElementOrder o = compute_element_order(mesh, c.volume, 1);
  const LaneBlocks<Real> lanes = make_lane_blocks<Real>(mesh, c, o);
  ASSERT_EQ(lanes.lane_tet.size(), lanes.blocks.size() * W);
  ASSERT_EQ(lanes.groups.size(), 1u);
  EXPECT_EQ(lanes.groups[0].begin, 0);
  EXPECT_EQ(lanes.groups[0].end, int32_t(lanes.blocks.size()));
  EXPECT_EQ(lanes.first_block, std::vector<int32_t>{0});
  std::vector<int> seen(mesh.tets.size(), 0);
  int padding = 0;
  for (size_t b = 0; b < lanes.blocks.size(); ++b)
    for (int l = 0; l < W; ++l) {
      const ElementBlock<Real>& B = lanes.blocks[b];
      const int32_t e = lanes.lane_tet[b * W + size_t(l)];
      if (e < 0) {
        ++padding;
        EXPECT_EQ(B.V[l], Real(0));
        for (int k = 0; k < 4; ++k) EXPECT_EQ(B.node4[k][l], B.node4[0][0]);
        continue;
      }
      ++seen[size_t(e)];
      EXPECT_EQ(lanes.tet_lane[size_t(e)], int32_t(b * W + size_t(l)));
      EXPECT_EQ(lanes.lane_dt[b * W + size_t(l)], c.dt[size_t(e)]);
      const Tet& t = mesh.tets[size_t(e)];
      for (int k = 0; k < 4; ++k)
        EXPECT_EQ(B.node4[k][l], t[size_t(k)]) << "the mesh's ids until compute_node_numbering";
      // Dm^-1 Dm = I, row-major.
      const Vec3 d[3] = {mesh.X[size_t(t[1])] - mesh.X[size_t(t[0])], mesh.X[size_t(t[2])] - mesh.X[size_t(t[0])],
                         mesh.X[size_t(t[3])] - mesh.X[size_t(t[0])]};
      for (int r = 0; r < 3; ++r)
        for (int col = 0; col < 3; ++col) {
          double s = 0;
          for (int k = 0; k < 3; ++k) s += double(B.Dinv[3 * r + k][l]) * d[col][k];
          EXPECT_NEAR(s, r == col ? 1.0 : 0.0, sizeof(Real) == 4 ? 1e-5 : 1e-12);
        }
    }
  for (int n : seen) EXPECT_EQ(n, 1);
  EXPECT_EQ(size_t(padding), lanes.blocks.size() * W - mesh.tets.size());
}
TEST(MakeLaneBlocks, EveryTetInOneLaneWithItsShapeAndPaddingWithoutVolumeFloat) { check_lane_blocks<float>(); }
TEST(MakeLaneBlocks, EveryTetInOneLaneWithItsShapeAndPaddingWithoutVolumeDouble) { check_lane_blocks<double>(); }

TEST(ComputeNodeNumbering, APermutationInFirstTouchOrderCutAt16) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(0.3, 0.1, 0.1), {30, 8, 8});
  const ElementConstants c = compute_element_constants(mesh, kSoft);
  const ElementOrder o = compute_element_order(mesh, c.volume, 2);
  const LaneBlocks<float> lanes = make_lane_blocks<float>(mesh, c, o);
  const NodeNumbering n = compute_node_numbering(lanes, o.n_parts, mesh.n_nodes());
  for (size_t i = 0; i < n.node_model.size(); ++i) ASSERT_EQ(n.node_given[size_t(n.node_model[i])], int32_t(i));
  int32_t next = 0;
  for (const ElementBlock<float>& B : lanes.blocks)
    for (int k = 0; k < 4; ++k)
      for (int l = 0; l < kLanes<float>; ++l) {
        const int32_t id = n.node_model[size_t(B.node4[k][l])];
        ASSERT_LE(id, next);
        if (id == next) ++next;
      }
  EXPECT_EQ(next, mesh.n_nodes());
  ASSERT_EQ(n.cut.size(), 3u);
  EXPECT_EQ(n.cut[0], 0);
  EXPECT_EQ(n.cut[1] % 16, 0);
  EXPECT_GT(n.cut[1], 0);
  EXPECT_EQ(n.cut[2], mesh.n_nodes());
}

// A quadratic layout numbers every node a lane touches, edge nodes too: a
// permutation of corners and edge nodes together, in first-touch order.
TEST(ComputeNodeNumbering, QuadraticBlocksNumberTheirEdgeNodesToo) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(0.3, 0.1, 0.1), {30, 8, 8});
  const TetMesh nodes = make_quadratic_mesh(mesh);
  const ElementConstants c = compute_element_constants(mesh, kSoft);  // (the linear tets' steps: unread here)
  const ElementOrder o = compute_element_order(mesh, c.volume, 2);
  const QuadraticLaneBlocks<double> lanes = make_quadratic_lane_blocks<double>(nodes, c, o);
  const auto n_nodes = int32_t(nodes.X.size());
  const NodeNumbering n = compute_node_numbering(lanes, o.n_parts, n_nodes);
  ASSERT_EQ(n.node_model.size(), nodes.X.size());
  for (size_t i = 0; i < n.node_model.size(); ++i) ASSERT_EQ(n.node_given[size_t(n.node_model[i])], int32_t(i));
  int32_t next = 0;
  for (const QuadraticBlock<double>& B : lanes.blocks)
    for (int k = 0; k < 10; ++k)
      for (int l = 0; l < kLanes<double>; ++l) {
        const int32_t id = n.node_model[size_t(B.node4[k][l])];
        ASSERT_LE(id, next);
        if (id == next) ++next;
      }
  EXPECT_EQ(next, n_nodes);
  EXPECT_EQ(n.cut.back(), n_nodes);
  EXPECT_EQ(n.cut[1] % 16, 0);
}

TEST(ComputeBoundarySets, SetsInModelIdsLoadsWeightedByMassAndOverlapsRefused) {
  ModelSpec spec = test::make_spec(make_regular_tet(), MaterialModel::StVK);
  const std::vector<int32_t> node_model{3, 2, 1, 0};  // model id of each given node
  const std::vector<double> mass{1, 2, 3, 4};         // by model id
  EssentialBc held;
  held.where.kind = NodeSelector::Kind::Nodes;
  held.where.nodes = {0, 1};
  NaturalLoad load;
  load.where.kind = NodeSelector::Kind::Nodes;
  load.where.nodes = {2, 3};  // model ids 1 and 0
  spec.essential = {held};
  spec.loads = {load};
  const BoundarySets s = compute_boundary_sets(spec, node_model, mass);
  EXPECT_EQ(s.essential.at(0).nodes, (std::vector<int32_t>{2, 3}));
  EXPECT_FALSE(s.essential[0].moving);
  EXPECT_EQ(s.constrained, (std::vector<int32_t>{2, 3}));
  EXPECT_EQ(s.loads.at(0).nodes, (std::vector<int32_t>{0, 1}));
  EXPECT_NEAR(s.loads[0].weight[0], 1.0 / 3, 1e-15);  // masses 1 and 2
  EXPECT_NEAR(s.loads[0].weight[1], 2.0 / 3, 1e-15);

  EssentialBc again = held;
  again.where.nodes = {1};
  spec.essential = {held, again};
  EXPECT_EQ(error_of([&] { compute_boundary_sets(spec, node_model, mass); }),
            "boundary conditions overlap: a node is held by two of them");
  EssentialBc none = held;
  none.name = "clamp";
  none.where.kind = NodeSelector::Kind::Box;
  none.where.lo = none.where.hi = Vec3(9.0);
  spec.essential = {none};
  EXPECT_EQ(error_of([&] { compute_boundary_sets(spec, node_model, mass); }),
            "boundary condition 0 ('clamp') selects no node");
}

TEST(CheckProxies, HandsGiveTheirDevicesAndEachChannelIsListedOnce) {
  ProxySpec tip;
  tip.name = "tip";
  tip.device = "stylus";
  ProxySpec thumb;
  thumb.name = "thumb";
  thumb.hand = "right";
  ProxySpec index = thumb;
  index.name = "index";
  HandSpec right;
  right.name = "right";
  right.device = "glove";
  right.pose.position = Vec3(0, 1, 0);
  index.pose.position = Vec3(0, 1.5, 0);
  const ProxySetup s = check_proxies({tip, thumb, index}, {right});
  EXPECT_EQ(s.devices, (std::vector<std::string>{"stylus", "glove"}));
  EXPECT_EQ(s.proxy_device, (std::vector<int32_t>{0, 1, 1}));
  EXPECT_EQ(s.proxy_hand, (std::vector<int32_t>{-1, 0, 0}));
  EXPECT_EQ(s.proxies[2].device, "glove");
  EXPECT_NEAR(s.proxy_offset[2].position.y, 0.5, 1e-15) << "in the hand's frame";

  thumb.device = "stylus";
  EXPECT_NE(error_of([&] { check_proxies({thumb}, {right}); }).find("differs from its hand's ('glove')"),
            std::string::npos);
  EXPECT_EQ(error_of([&] { check_proxies({tip}, {right}); }), "hand 0 ('right'): no proxy belongs to it");
  EXPECT_EQ(error_of([&] { check_proxies({tip, tip}, {}); }), "proxy 1 ('tip'): name used twice (also proxy 0)");
  tip.geometry.radius = 0;
  EXPECT_EQ(error_of([&] { check_proxies({tip}, {}); }),
            "proxy 0 ('tip'): radius must be finite and > 0 m, got 0.000000");
}

TEST(CheckSettings, NamesEachSettingOutOfRange) {
  Effects effects;
  IntegratorSpec integrator;
  EXPECT_EQ(error_of([&] { check_settings(effects, integrator); }), "");
  effects.damping = true;
  effects.alpha = -1;
  EXPECT_EQ(error_of([&] { check_settings(effects, integrator); }), "damping alpha must be >= 0 1/s, got -1.000000");
  effects.alpha = 1;
  integrator.safety = 1.5;
  EXPECT_EQ(error_of([&] { check_settings(effects, integrator); }),
            "integrator.safety must lie in (0, 1], got 1.500000");
  integrator.safety = 0.9;
  integrator.threads = 0;
  EXPECT_EQ(error_of([&] { check_settings(effects, integrator); }), "integrator.threads must be >= 1");
}

TEST(ComputeEmbeddedNodes, AVertexFollowsItsNodesInModelIdsAndAnotherMeshsNodeIsRefused) {
  EmbeddedSurface surface;
  surface.nodes = {{0, 1, 2, 3}, {3, 2, 1, 0}};
  const std::vector<int32_t> node_model{3, 2, 1, 0};
  EXPECT_EQ(compute_embedded_nodes(surface, node_model), (std::vector<Tet>{{3, 2, 1, 0}, {0, 1, 2, 3}}));
  surface.nodes[1][2] = 4;
  EXPECT_EQ(error_of([&] { compute_embedded_nodes(surface, node_model); }),
            "surface vertex 1 follows node 4, which the mesh lacks (bound to another mesh)");
}

}  // namespace
}  // namespace tactile

// Hot loops of the explicit step, lane-blocked so that the compiler
// vectorises the material math across elements, built once per x86-64 ISA
// level and picked at run time (dispatch.cpp).
//
// Elements are stored in blocks of W lanes (W = 64 bytes / sizeof(Real): one
// AVX-512 register, two AVX2 ones). The state's node arrays are interleaved
// xyz, (n x 3); the element pass reads and writes node arrays padded to four
// entries per node (Node4), so that a lane loads or adds a whole corner as
// one vector.
#pragma once

#include <cstddef>
#include <cstdint>
#include <new>
#include <string_view>

#include "core/material.hpp"

namespace tactile {

template <class Real>
inline constexpr int kLanes = 64 / static_cast<int>(sizeof(Real));

template <class Real>
struct alignas(64) ElementBlock {
  static constexpr int W = kLanes<Real>;
  // Where each corner's node starts in a Node4 array, in Reals: 4 x node id.
  // (So that a corner's address is one scaled index, base + node4 x
  // sizeof(Real), with no shift of its own: a block has 128 corner loads and
  // adds. An int32 holds 4 x id for up to 2^29 nodes, far more than memory
  // holds.) Padding lanes: lane 0's corner 0, all four. (n_blocks x 4 x W)
  int32_t node4[4][W];
  Real Dinv[9][W];  // inverse rest edge matrix Dm^-1, row-major, Dm = [X1-X0 X2-X0 X3-X0]
  Real V[W];        // rest volume [m^3]; 0 in padding lanes (a block's Lame parameters are its group's)
};

// A block of W straight-sided quadratic tets (core/quadratic.hpp): ten node
// ids per lane, corners then edge nodes in VTK's order, as ElementBlock's
// (4 x node id; padding lanes: lane 0's corner 0, all ten), the corners'
// Dm^-1 and the rest volume. The four quadrature points' gradients follow
// from Dm^-1 and constants (d N / d X = Dm^-T d N / d xi), so a straight
// element streams 10 ids, 9 entries and a volume a lane.
template <class Real>
struct alignas(64) QuadraticBlock {
  static constexpr int W = kLanes<Real>;
  int32_t node4[10][W];
  Real Dinv[9][W];  // inverse rest edge matrix of the corners, row-major
  Real V[W];        // rest volume [m^3]; 0 in padding lanes
};

// One node's vector padded to four entries (x, y, z, 0), aligned to its size
// so that it never straddles a cache line.
template <class Real>
struct alignas(4 * sizeof(Real)) Node4 {
  Real v[4];
};

// Allocator for the node arrays the kernels stream through in whole vectors:
// cache-line aligned, so that a W-node group never straddles an extra line.
template <class T>
struct CacheAlignedAllocator {
  using value_type = T;
  CacheAlignedAllocator() = default;
  template <class U>
  CacheAlignedAllocator(const CacheAlignedAllocator<U>&) {}
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(64))); }
  void deallocate(T* p, size_t) { ::operator delete(p, std::align_val_t(64)); }
  friend bool operator==(const CacheAlignedAllocator&, const CacheAlignedAllocator&) { return true; }
};

// Elastic forces of blocks [begin, end), all of one material (Lame
// parameters lambda, mu [Pa]), at displacements u (n_nodes): f -= dU/du,
// accumulated into f (n_nodes; the 4th entries stay 0). The elastic energy
// comes almost free with the stress, so the energy guard can check every step.
struct ElasticSums {
  double energy = 0;     // sum V psi(F) [J]
  int32_t inverted = 0;  // lanes with det F <= 0, counted only for models that cannot invert
};
template <class Real>
using ForcesFn = ElasticSums (*)(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda, Real mu,
                                 const Node4<Real>* u, Node4<Real>* f);

// The same for quadratic blocks: f -= dU/du with U = sum over the four
// quadrature points of V/4 psi(F_q) (core/quadratic.hpp, compute_p2_forces,
// is its scalar reference); `inverted` counts lanes with det F <= 0 at some point.
template <class Real>
using QuadraticForcesFn = ElasticSums (*)(const QuadraticBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda,
                                          Real mu, const Node4<Real>* u, Node4<Real>* f);

// Elastic energy V psi(F) per lane of blocks [begin, end), of one material,
// at displacements u (n_nodes x 3), written to energy[(b - begin) * W + lane];
// and det F per lane to J (may be null). Not a hot loop: energy reports and
// fault diagnosis.
template <class Real>
using EnergyFn = void (*)(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda, Real mu,
                          const Real* u, double* energy, Real* J);

// The critical step of blocks [begin, end), all of one material model, at
// displacements u (n_nodes x 3): the least over their lanes of
//   dt_rest x max(min(h / h_rest, 1), 0.05) / sqrt(k),
// with dt_rest the lane's exact rest value (lane_dt, n_blocks x W; +inf in
// padding lanes), h / h_rest its smallest altitude over the rest one, and k
// how much its material has stiffened (material::stiffening); +inf if no lane
// counts, and for linear elements (small strain has one stiffness: the rest
// step holds). Stepper::advance refreshes its estimate with it as the body deforms.
template <class Real>
using CriticalFn = double (*)(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u,
                              const double* lane_dt);

// Newmark predictor, eq. (7), over nodes [begin, end):
//   u += dt v + dt^2/2 a;  v <- v + dt/2 a (the half-step velocity eq. (9) completes);
// and the new u padded into u4 for the element pass.
template <class Real>
using PredictFn = void (*)(int32_t begin, int32_t end, Real dt, Real* u, Real* v, const Real* a, Node4<Real>* u4);

// u4[i] = (u_i, 0) over nodes [begin, end), u (n x 3): the element pass's copy
// of u when no predictor wrote it.
template <class Real>
using PadFn = void (*)(int32_t begin, int32_t end, const Real* u, Node4<Real>* u4);

// Corrector, eqs. (8)-(10) with D = alpha M, over nodes [begin, end):
//   a = (f / m + g - alpha v_half) / (1 + alpha dt / 2);  v = v_half + dt/2 a.
// f is the sum of the force arrays that hold a node, in the order listed for
// its 16 nodes: f[group_offset[k] + i] for k in [group_begin[i / 16],
// group_begin[i / 16 + 1]). The corrector sets every entry it reads back to
// 0, so the next element pass adds into zeros without a clearing pass.
// begin and end are multiples of 16, or end is the last node.
template <class Real>
struct CorrectArgs {
  int32_t begin, end;
  Real dt;
  Node4<Real>* f;               // the force arrays [N]
  const int32_t* group_begin;   // per 16 nodes, into group_offset
  const int64_t* group_offset;  // offsets into f of the arrays that hold them
  const Real* inv_m;            // 1/m per node [1/kg] (n)
  const Real* m;                // m per node [kg] (n)
  Real g[3];                    // [m/s^2]
  Real alpha;                   // [1/s]
  const Real* u;                // for the gravity potential
  Real* v;
  Real* a;
};
struct CorrectSums {
  double abs_a = 0;  // sum |a|: non-finite when any value is
  double mv2 = 0;    // sum m |v|^2 = 2 x kinetic energy [J]
  double mgu = 0;    // sum m g.u [J], with gravity only
  double ma2 = 0;    // sum m |a|^2, for the central-difference energy
};
template <class Real>
using CorrectFn = CorrectSums (*)(const CorrectArgs<Real>& args);

template <class Real>
struct KernelTable {
  ForcesFn<Real> forces[kMaterialModelCount];
  QuadraticForcesFn<Real> quadratic_forces[kMaterialModelCount];
  EnergyFn<Real> energy[kMaterialModelCount];
  CriticalFn<Real> critical[kMaterialModelCount];
  PredictFn<Real> predict;
  PadFn<Real> pad;
  CorrectFn<Real> correct[2][2];  // [gravity][damping]: a scene pays only for what it has
};

// The table for the best ISA this CPU runs, or the one forced by select_isa.
template <class Real>
const KernelTable<Real>& kernels();
// The table of one ISA level ("baseline", "v3", "v4"), or null if unknown or
// not supported by this CPU: for tests that compare the levels.
template <class Real>
const KernelTable<Real>* kernels_for(std::string_view isa);
std::string_view kernel_isa();
// Forces an ISA level ("baseline", "v3", "v4"); false if unknown or unsupported.
bool select_isa(std::string_view name);

}  // namespace tactile

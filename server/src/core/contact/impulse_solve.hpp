// The contact impulses: the paper's velocity projection (section 5.1, eq.
// (11)) for all of a step's contact points at once. Each point's normal
// velocity relative to its proxy is set to zero where it points into the
// proxy, by an impulse along the normal that never pulls (its running sum
// stays at or above zero); Coulomb friction, where a point has it, takes the
// tangential velocity away by an impulse held within mu times the normal one
// (stick, or slide at the bound). A point's impulse J is shared over the
// nodes it moves, dv_k = w_k J / m_k, and its opposite goes to the proxy's
// coupled body (core/coupling.hpp), if it has one.
//
// Points that share nodes (a face's point and its corner's) or a coupled
// body (each impulse changes the body's velocity that the others see) are
// solved together by projected Gauss-Seidel: swept until no velocity changes
// by more than a given fraction (a millionth for proxies) of the first
// sweep's largest change. One group is
// a kinematic proxy's points, or a coupled body's; one proxy's points can
// always all be met (the nodes moving with it), so the sweeps converge; two
// proxies pinching a node cannot both be, and they are solved one after the
// other.
//
// A solve may start from a guess (a warm start: the step before's impulses
// of points that persist), scaled so that it starts no higher than from none
// (warm_scale).
//
// Pure: it reads the points, each slot's velocity and mass, and the bodies;
// it writes the points' impulses, the slots' velocity changes and the
// bodies' velocities. Contact (core/contact/contact.hpp) finds the points
// and applies the changes.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/contact/contact_state.hpp"

namespace tactile {

// The most nodes a contact point moves: an embedded triangle's three
// vertices, four nodes each, and (between bodies) the vertex's four.
constexpr size_t kPointCarriers = 16;

// A contact point inside a proxy at t_{n+1}: a free surface node, a point
// of a face, x = sum w_c x_c over its corners, or of an embedded surface,
// over the nodes its vertices follow. Its nodes are slots: indices into the
// solve's per-slot arrays.
struct ContactPoint {
  int32_t proxy;
  int32_t body;                              // its proxy's coupled body, -1 for a kinematic proxy
  Vec3 r;                                    // from the body's origin to x (coupled) [m]
  std::array<int32_t, kPointCarriers> slot;  // its free corners' slots, -1 past the last (a node: slot[0], weight 1)
  std::array<double, kPointCarriers> w;      // their weights
  Vec3 x;                                    // world position [m]
  Vec3 n;                                    // outward normal (world)
  Vec3 vp;                                   // the proxy's velocity at x [m/s]
  Vec3 v_held;                               // velocity its held corners give it (sum w_c v_c) [m/s]
  double inv_mass;                           // sum w_c^2 / m_c over its free corners [1/kg]
  double mu;                                 // Coulomb friction coefficient, 0 without
  double jn = 0;                             // normal impulse given so far [N s] (never negative)
  Vec3 jt{0.0};                              // tangential impulse so far (|jt| <= mu jn)
};

// The proxy's velocity at a point: its coupled body's (as the solve has it
// so far), or the kinematic proxy's (c.vp).
Vec3 proxy_velocity(const std::vector<CoupledBodyState>& bodies, const ContactPoint& c);

class ImpulseSolve {
 public:
  // Room for `slots` slots, `groups` groups (proxies plus coupled bodies)
  // and `points` points: solve() allocates nothing within them.
  void reserve(size_t slots, size_t groups, size_t points);

  // The impulses of `points`, grouped by proxy (the first n_proxies groups)
  // or by coupled body (bodies[i]: group n_proxies + i). v[k] and mass[k]:
  // slot k's velocity before contact [m/s] and its mass [kg] (read only for
  // the slots the points name). Sums each point's impulse into its jn and
  // jt, each slot's velocity change into dv(k) (the slots in moved()), and
  // each body's reaction into its next.v and next.w.
  // It starts from the points' jn and jt: zero (cold), or a guess such as
  // the step before's impulses scaled by warm_scale() (warm), given first.
  // The sweeps stop when no velocity changes by more than `tolerance` times
  // the first sweep's largest change (or, warm, the largest speed at which a
  // point approached before its guess), or by more than `floor` [m/s].
  void solve(std::vector<ContactPoint>& points, size_t n_proxies, std::vector<CoupledBodyState>& bodies,
             const std::vector<Vec3>& v, const std::vector<double>& mass, double tolerance = 1e-6, double floor = 0);

  // The factor in [0, 1] by which the points' jn and jt (a guess: another
  // step's impulses) lower most the solve's objective, the kinetic energy
  // of their slots less each impulse's work against its point's vp (which,
  // for vp = 0, is the kinetic energy alone). Scaled so, a warm solve starts
  // no higher than a cold one, and each sweep only lowers it. For points
  // of kinematic proxies, or between bodies (c.body < 0).
  double warm_scale(const std::vector<ContactPoint>& points, const std::vector<Vec3>& v,
                    const std::vector<double>& mass);

  // Whether the latest solve() stopped by its tolerance in every group, not
  // at its most sweeps (a group whose points fight each other: its
  // velocities are left still changing).
  bool settled() const { return settled_; }

  // The slots given a velocity change since the last clear(), and each one's.
  const std::vector<int32_t>& moved() const { return moved_; }
  const Vec3& dv(int32_t slot) const { return dv_[size_t(slot)]; }
  // Forgets the changes (the next solve starts from none).
  void clear();

 private:
  Vec3 point_velocity(const ContactPoint& c, const std::vector<Vec3>& v) const;
  void give(std::vector<CoupledBodyState>& bodies, const ContactPoint& c, const Vec3& J,
            const std::vector<double>& mass);

  std::vector<Vec3> dv_;                           // per slot [m/s]
  std::vector<Vec3> guess_;                        // per slot: sum w J of a guess (warm_scale) [N s]
  std::vector<int32_t> moved_;                     // slots with a dv_
  std::vector<uint8_t> moved_flag_;                // per slot: in moved_
  std::vector<int32_t> order_;                     // the points' indices, by group
  std::vector<int32_t> group_begin_, group_fill_;  // per group: its range in order_
  bool settled_ = true;
};

}  // namespace tactile

// Explicit Newmark time stepping, eqs. (7)-(10), assembled from only the
// effects a model has.
//
// One step (step(), read as its list of passes): predict u and the half-step
// velocity (eq. 7), impose essential BCs, elastic forces R(u) (lane-blocked
// kernels), natural loads, then the diagonal solve of eq. (10) with gravity
// and damping only if present, proxy contact only if there are proxies
// (core/contact/contact.hpp), the essential BCs' velocities and
// accelerations, and contact between bodies or within one only if the
// effects ask for it (core/contact/body_contact.hpp).
// Each step also checks for non-finite values, inverted elements (for models
// that cannot take them) and energy growth beyond the work done
// (core/energy_ledger.hpp), and reports a Fault instead of going on;
// advance() plans its sub-steps on the critical step (core/critical_step.hpp).
//
// The stepper owns a preallocated workspace: a step allocates nothing, and
// all a step carries to the next is in the State (core/state.hpp). It starts
// no threads: a ParallelFor from the application layer splits the element
// and node passes by a plan made once (core/step_plan.hpp). Split, a step is
// one job per part (predictor, essential positions, elastic forces and,
// without loads, the corrector), whose parts wait on each other only for the
// nodes and force arrays they share (elastic_part; core/step_sync.hpp).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/contact/body_contact.hpp"
#include "core/contact/contact.hpp"
#include "core/critical_step.hpp"
#include "core/energy_ledger.hpp"
#include "core/model.hpp"
#include "core/parallel_for.hpp"
#include "core/state.hpp"
#include "core/step_plan.hpp"
#include "core/step_sync.hpp"

namespace tactile {

// The passes of a step, for cost accounting by a StepProbe.
enum class Pass : uint8_t { Predict, Essential, Elastic, Loads, Correct, Contact, BodyContact, Guard };
inline constexpr int kPassCount = 8;
// How far the critical step may fall before advance() stops with a fault
// (Stepper::check_collapse): below kCollapsedStep of the step at rest for
// longer than kCollapseGrace of simulated time, or below kCrushedStep at once.
// A strike under a bounded load (a coupled proxy at a hand's speed) crushes
// the elements it hits for a few milliseconds, splitting the steps, and they
// recover; a prescribed motion driving a body into a proxy squashes them on
// without bound.
inline constexpr double kCollapsedStep = 1e-2;
inline constexpr double kCrushedStep = 1e-3;
inline constexpr double kCollapseGrace = 5e-3;  // [s]
const char* to_string(Pass p);

// Told when each pass of a step starts and ends; the application layer times
// them (the core reads no clock).
class StepProbe {
 public:
  virtual ~StepProbe() = default;
  virtual void enter(Pass p) = 0;
  virtual void leave(Pass p) = 0;
};

struct AdvanceReport {
  int32_t substeps = 0;
  double dt = 0;             // sub-step used [s]
  double dt_critical = 0;    // estimate for the current configuration [s]
  bool subdivided = false;   // a fixed dt above the estimate was split
  bool interrupted = false;  // the caller's interrupt stopped it between two steps
  Fault fault;
};

template <class Real>
class Stepper {
 public:
  explicit Stepper(const Model<Real>& model, ParallelFor* parallel = nullptr);

  const Model<Real>& model() const { return model_; }
  // A body at rest in this model, its proxies and hands held at their scene
  // poses: the State every run starts from (core/state.hpp).
  State<Real> make_state() const;

  // One step of dt [s]. After a fault (s.fault), returns it again until clear_fault(s).
  Fault step(State<Real>& s, double dt);

  // Covers frame_dt [s] with as many equal sub-steps as stability needs
  // (auto step), or with the scene's fixed step, subdivided or refused when
  // it exceeds the critical step of the current configuration.
  // `interrupt`, when set, is asked between steps: true stops the interval
  // there (report.interrupted), the state consistent at the time reached.
  AdvanceReport advance(State<Real>& s, double frame_dt, const std::function<bool()>& interrupt = {});

  // Sets a consistent with the forces at s.t, eq. (1): M a = F - R(u) - D v,
  // and the constrained nodes' v, a and reaction. step() does this itself when
  // it starts from a state (first step, or after clear_fault()).
  void apply_initial_acceleration(State<Real>& s);

  // Critical step of the current configuration [s] (core/critical_step.hpp).
  double compute_critical_dt(const State<Real>& s) const { return critical_.compute(s); }

  // All energies from a full pass (not the hot path).
  Energy compute_energy(const State<Real>& s) const;
  // Elastic energy density V psi per tet [J] (n_tets).
  std::vector<double> compute_element_energy(const State<Real>& s) const;

  // Forgets s.fault; the next step starts again from s (the energy account
  // and the critical step anew). The energies of the latest step, from sums
  // the step computes anyway, are s.energy.latest.
  void clear_fault(State<Real>& s) const;
  void set_probe(StepProbe* probe) { probe_ = probe; }
  int32_t parts() const { return n_parts_; }

  // The contact pass: what moves the proxies and hands of a state (set by
  // the application from device inputs or scripts); what each felt in the
  // latest step is in s.contact.
  Contact<Real>& contact() { return contact_; }
  const Contact<Real>& contact() const { return contact_; }
  // Contact between bodies and within one, when the effects ask for it.
  const BodyContact<Real>& body_contact() const { return body_contact_; }
  BodyContact<Real>& body_contact() { return body_contact_; }

 private:
  using Part = StepPlan::Part;
  using Region = StepPlan::Region;
  using Chunk = StepPlan::Chunk;
  using EssentialEntry = StepPlan::EssentialEntry;
  // The entries [begin, end) of essential_entries_.
  void apply_essential_positions(State<Real>& s, double t, size_t begin, size_t end);
  // Part q's predictor and essential positions of this step, run by this
  // thread unless another has claimed them; returns once they are done.
  void ensure_predicted(int32_t q);
  // Part q's own blocks, the same way.
  void ensure_own(int32_t q);
  // Claims and runs pair k's middle chunks from one side until none is left.
  void claim_chunks(int32_t k, int side);
  // Returns once region r holds this step's forces in full, doing what no
  // thread has claimed yet.
  void ensure_region(int32_t r);
  CorrectSums correct_range(int32_t begin, int32_t end);
  void apply_essential_rates(State<Real>& s, double t, double dt);
  void apply_loads(State<Real>& s, double t);
  void add_load_force(int32_t node, const Vec3& force);

  // The passes of step(), in order.
  void open_energy_account(State<Real>& s, double dt);
  void keep_work_positions(const State<Real>& s);
  void predict_and_add_elastic_forces(State<Real>& s);
  void correct(State<Real>& s);
  ContactSums apply_contact(State<Real>& s, double dt);
  // A fault when the critical step has collapsed below kCollapsedStep of the step at rest.
  Fault check_collapse(State<Real>& s, double dt_critical);
  void close_energy_account(State<Real>& s, double dt, const ContactSums& contact);
  Fault check_step(State<Real>& s);

  Fault make_fault(Fault::Kind kind, State<Real>& s, std::string message, std::vector<int32_t> elements);
  std::vector<int32_t> find_nonfinite_elements(const State<Real>& s) const;
  std::vector<int32_t> find_inverted_elements(const State<Real>& s) const;
  std::vector<int32_t> find_top_energy_elements(const State<Real>& s, size_t count) const;
  void run_parts(void (*fn)(void*, int32_t), void* ctx);
  void run_elastic();
  // Forces of blocks [begin, end) into region r; its sums into elastic_[r].
  void elastic_blocks(int32_t begin, int32_t end, int32_t r);
  void enter(Pass p) {
    if (probe_) probe_->enter(p);
  }
  void leave(Pass p) {
    if (probe_) probe_->leave(p);
  }

  static void predict_part(void* ctx, int32_t p);
  static void pad_part(void* ctx, int32_t p);
  static void elastic_part(void* ctx, int32_t p);
  static void correct_part(void* ctx, int32_t p);

  const Model<Real>& model_;
  ParallelFor* parallel_;
  StepProbe* probe_ = nullptr;
  const KernelTable<Real>& kernels_;
  CorrectFn<Real> correct_;
  Contact<Real> contact_;
  BodyContact<Real> body_contact_;
  CriticalStep<Real> critical_;
  StepPlan plan_;  // how the step's work splits over threads (core/step_plan.hpp)
  int32_t n_parts_ = 1;

  // Workspace, sized once.
  std::vector<Node4<Real>, CacheAlignedAllocator<Node4<Real>>> u4_;  // u for the element pass [m] (n_nodes)
  std::vector<Node4<Real>, CacheAlignedAllocator<Node4<Real>>> f_;   // the regions' force arrays [N]
  std::unique_ptr<PairShare[]> shares_;                              // per pair of parts
  std::vector<ElasticSums> elastic_;                                 // per region, whichever thread filled it
  std::vector<CorrectSums> correct_sums_;                            // per part
  std::vector<Vec3> u_before_;                                       // constrained and loaded nodes' u at t_n [m]
  std::vector<Real> a_prescribed_;                                   // prescribed accelerations (n_constrained x 3)
  std::vector<Real> v_prescribed_;                                   // prescribed velocities (n_constrained x 3)
  std::vector<int32_t> loaded_;                                      // loaded node ids, flattened over loads
  // The split step's hand-offs (core/step_sync.hpp).
  std::unique_ptr<OnceClaim[]> predicted_;     // per part: its nodes predicted, its essential positions set
  std::unique_ptr<OnceClaim[]> own_claim_;     // per part: its own blocks
  std::unique_ptr<RegionDone[]> region_done_;  // per region
  uint32_t epoch_ = 0;                         // steps that predicted inside the element pass
  bool fused_ = false;                         // the element pass predicts first (see elastic_part)
  bool fused_correct_ = false;                 // and corrects last

  // Per-step context for the part functions.
  State<Real>* cur_ = nullptr;
  Real cur_dt_ = 0;
  double cur_t1_ = 0;  // the time the step reaches [s]

  struct StepSums {
    ElasticSums elastic;
    CorrectSums correct;
  };
  StepSums step_sums_;              // the passes' sums of the latest step, for its guard
  double essential_mv2_delta_ = 0;  // constrained nodes' change of m |v|^2 in this step
  double essential_ma2_delta_ = 0;  // and of m |a|^2
  double energy_floor_ = 0;         // the balance's resolution in Real (energy_floor) [J]
};

}  // namespace tactile

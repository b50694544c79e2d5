// The core from Python (import tactile): scenes loaded by the same loader as
// the CLIs (the same schema and the same errors naming the field), a
// Simulation stepped by the same code, and its node arrays as read-only NumPy
// views in the mesh's numbering. pybind11; built by scikit-build-core from
// server/CMakeLists.txt (server/pyproject.toml).
//
// The views: the model keeps its nodes in its own order (core/model.hpp), so
// a per-node array in the mesh's order is gathered when it is first read
// after a step, into a buffer this object owns, and handed out as a
// read-only view of that buffer: the array as of the step it was read at.
// A buffer is never written again while a view of it lives (the next step's
// gather takes a free one), so a view never changes under its reader: not
// in another thread, not inside a NumPy call that lets the GIL go (a view
// that followed the steps in place was read half-written there).
//
// Threads: calls on one Simulation are serialised by its lock (a second
// thread waits for the first's advance() to end). A long advance() checks
// for signals ten times a second: Ctrl-C stops it between two steps, at the
// time reached.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "tactile_version.hpp"

#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/headless.hpp"
#include "app/vtu.hpp"
#include "core/model.hpp"
#include "live/resim.hpp"
#include "mesh/mesh_error.hpp"
#include "record/mcap.hpp"
#include "scene/parameters.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"
#include "study/accuracy.hpp"
#include "study/stability.hpp"

namespace py = pybind11;

namespace tactile {
namespace {

// A scene's bodies as Python sees them: name, and numpy-ready slices of the
// node, tet and fine-surface arrays (one body over everything in a scene of one).
py::list bodies_list(const std::vector<BodySpec>& bodies) {
  py::list out;
  for (const BodySpec& b : bodies) {
    py::dict d;
    d["name"] = b.name;
    d["nodes"] = py::slice(b.node_begin, b.node_end, 1);
    d["tets"] = py::slice(b.tet_begin, b.tet_end, 1);
    d["fine_vertices"] = py::slice(b.fine_vertex_begin, b.fine_vertex_end, 1);
    d["fine_triangles"] = py::slice(b.fine_triangle_begin, b.fine_triangle_end, 1);
    out.append(d);
  }
  return out;
}

using PoseTuple = std::pair<std::array<double, 3>, std::array<double, 4>>;  // position, quaternion (w, x, y, z)

Pose to_pose(const std::array<double, 3>& position, const std::optional<std::array<double, 4>>& orientation) {
  Pose p;
  p.position = Vec3(position[0], position[1], position[2]);
  if (orientation) {
    const auto& q = *orientation;
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(n > 0) || !std::isfinite(n)) throw py::value_error("orientation: not a quaternion (w, x, y, z) of norm > 0");
    p.orientation = Quat(q[0] / n, q[1] / n, q[2] / n, q[3] / n);
  }
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(p.position[c])) throw py::value_error("position: must be finite");
  return p;
}

PoseTuple from_pose(const Pose& p) {
  return {{p.position.x, p.position.y, p.position.z},
          {p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z}};
}

std::vector<Scene> pick(std::vector<Scene> scenes, const std::optional<std::string>& variant, const std::string& path) {
  if (!variant) return scenes;
  return {pick_variant(std::move(scenes), *variant, path)};
}

// A read-only (rows x cols) float64 view of `data`, kept alive by `owner`.
py::array view(const double* data, size_t rows, size_t cols, py::handle owner) {
  py::array a(py::dtype::of<double>(), {rows, cols}, {cols * sizeof(double), sizeof(double)}, data, owner);
  a.attr("setflags")(py::arg("write") = false);
  return a;
}

py::dict energy_dict(const Energy& e) {
  py::dict d;
  d["kinetic"] = e.kinetic;
  d["elastic"] = e.elastic;
  d["gravity"] = e.gravity;
  d["work_loads"] = e.work_loads;
  d["work_essential"] = e.work_essential;
  d["work_contact"] = e.work_contact;
  d["dissipated"] = e.dissipated;
  d["discrete"] = e.discrete;
  d["restated"] = e.restated;
  d["balance"] = e.balance();
  return d;
}

py::object fault_object(const Fault& f) {
  if (!f) return py::none();
  py::dict d;
  d["kind"] = to_string(f.kind);
  d["message"] = f.message;
  d["step"] = f.step;
  d["t"] = f.t;
  d["elements"] = f.elements;
  return d;
}

py::dict report_dict(const AdvanceReport& r) {
  py::dict d;
  d["substeps"] = r.substeps;
  d["dt"] = r.dt;
  d["dt_critical"] = r.dt_critical;
  d["subdivided"] = r.subdivided;
  d["fault"] = fault_object(r.fault);
  return d;
}

// Holds a Simulation's lock for a call. Whoever waits for it lets the GIL go
// first: the holder takes the GIL again while it holds the lock (to check for
// signals, and when its step returns), so waiting with it would deadlock. Recursive: a call may make another (step() ->
// advance()).
class Busy {
 public:
  explicit Busy(std::recursive_mutex& m) : lock_(m, std::try_to_lock) {
    if (lock_.owns_lock()) return;
    py::gil_scoped_release release;
    lock_.lock();
  }

 private:
  std::unique_lock<std::recursive_mutex> lock_;
};

// A Simulation for one expression, its lock held: `s.sim()->time()`.
class Locked {
 public:
  Locked(std::recursive_mutex& m, Simulation& sim) : busy_(m), sim_(sim) {}
  Simulation* operator->() const { return &sim_; }
  Simulation& operator*() const { return sim_; }

 private:
  Busy busy_;
  Simulation& sim_;
};

// Asked between steps without the GIL: every 0.1 s of wall time it takes the
// GIL and checks for signals (Ctrl-C); a handler that raises stops the
// advance, and the exception is rethrown once the step's arrays are published.
class SignalCheck {
 public:
  bool operator()() {
    const auto now = std::chrono::steady_clock::now();
    if (now < next_) return false;
    next_ = now + std::chrono::milliseconds(100);
    py::gil_scoped_acquire gil;
    raised_ = PyErr_CheckSignals() != 0;
    return raised_;
  }
  // Raises what the signal handler raised, if it did.
  void rethrow() const {
    if (raised_) throw py::error_already_set();
  }

 private:
  std::chrono::steady_clock::time_point next_ = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
  bool raised_ = false;
};

// One per-node array as views show it (n_nodes x 3): the buffers gathered
// into, each kept while a view of it lives (its capsule holds a reference).
class Published {
 public:
  // A view of the array at `generation`, gathered by `gather` if the latest
  // buffer is older.
  template <class Gather>
  py::array view(uint64_t generation, Gather gather) {
    if (current_ < 0 || generation != generation_) {
      // In place only while no view shows it; else a free buffer, or a new one.
      if (current_ < 0 || pool_[size_t(current_)].use_count() > 1) {
        current_ = -1;
        for (size_t k = 0; k < pool_.size() && current_ < 0; ++k)
          if (pool_[k].use_count() == 1) current_ = int64_t(k);
        if (current_ < 0) {
          pool_.push_back(std::make_shared<std::vector<double>>());
          current_ = int64_t(pool_.size() - 1);
        }
      }
      gather(*pool_[size_t(current_)]);
      generation_ = generation;
    }
    using Buffer = std::shared_ptr<std::vector<double>>;
    const Buffer& b = pool_[size_t(current_)];
    py::capsule owner(new Buffer(b), [](void* p) { delete static_cast<Buffer*>(p); });
    return tactile::view(b->data(), b->size() / 3, 3, owner);
  }

 private:
  std::vector<std::shared_ptr<std::vector<double>>> pool_;
  int64_t current_ = -1;  // the latest gathered (index into pool_)
  uint64_t generation_ = 0;
};

// The Python face of a Simulation: the simulation, and the mesh-ordered
// arrays its views show.
class PySimulation {
 public:
  // A report's impulse sums at a moment, and (means()) the mean force and
  // torque between two such moments [N, N m] in `impulse`, `angular_impulse`.
  struct ImpulseMark {
    Vec3 impulse{0.0}, angular_impulse{0.0};
    double elapsed = 0;
  };

  explicit PySimulation(const Scene& scene) : scene_(scene), sim_(scene.spec) {
    // Each node's contact impulse is summed from the start, for write_vtu's contact_force (a few adds per
    // node pushed, as a headless run that writes it does).
    sim_.track_contact_forces(true);
    proxy_taken_.assign(scene_.proxy_script.size(), false);
    hand_taken_.assign(scene_.hand_script.size(), false);
    const TetMesh& mesh = sim_.mesh();
    per_tet_ = size_t(mesh.nodes_per_tet());
    tets_.reserve(per_tet_ * size_t(sim_.n_tets()));
    for (size_t e = 0; e < mesh.tets.size(); ++e)
      for (int k = 0; k < mesh.nodes_per_tet(); ++k) tets_.push_back(mesh.node(e, k));
  }

  // `seconds` on: with `scripts`, a scene's scripted proxies and hands (those
  // not moved from Python since) follow their scripts, in control intervals
  // of at most HeadlessOptions::control_interval set as tactile-sim run sets
  // them, so that advance(frame_dt) in a loop steps as its frames do. The
  // reports' mean over the call is kept for proxy_reports and device_reports.
  py::dict advance(double seconds, bool scripts = true) {
    if (!(seconds > 0) || !std::isfinite(seconds))
      throw py::value_error("advance: seconds must be finite and > 0, got " + std::to_string(seconds));
    const Busy busy(mutex_);
    const std::vector<ImpulseMark> proxies0 = marks(sim_.proxy_reports()), devices0 = marks(sim_.device_reports());
    AdvanceReport r;
    SignalCheck signals;
    {
      py::gil_scoped_release release;
      if (!scripts || !scripted()) {
        r = sim_.advance(seconds, std::ref(signals));
      } else {
        const double most = HeadlessOptions{}.control_interval;
        const auto pieces = int32_t(std::max(1.0, std::ceil(seconds / most * (1.0 - 1e-12))));
        const double interval = seconds / double(pieces);
        for (int32_t k = 0; k < pieces && !r.fault && !r.interrupted; ++k) {
          const double t0 = sim_.time();
          drive(t0, t0 + interval);
          const AdvanceReport piece = sim_.advance(interval, std::ref(signals));
          r.substeps += piece.substeps;
          r.dt = piece.dt > 0 ? piece.dt : r.dt;
          r.dt_critical = piece.dt_critical;
          r.subdivided = r.subdivided || piece.subdivided;
          r.interrupted = piece.interrupted;
          r.fault = piece.fault;
        }
      }
    }
    proxy_means_ = means(proxies0, sim_.proxy_reports());
    device_means_ = means(devices0, sim_.device_reports());
    ++generation_;
    signals.rethrow();
    return report_dict(r);
  }

  // advance(seconds), `count` times in a loop in C++: the wall time of each
  // call [s], for comparing a loop of advance() from Python with the core's own
  // (server/bench/python_api_bench.py).
  py::array_t<double> time_advance(double seconds, int32_t count) {
    if (!(seconds > 0) || !std::isfinite(seconds) || count < 1)
      throw py::value_error("time_advance: seconds must be finite and > 0 and count >= 1");
    const Busy busy(mutex_);
    py::array_t<double> out(count);
    double* w = out.mutable_data();
    SignalCheck signals;
    for (int32_t k = 0; k < count; ++k) {
      const auto t0 = std::chrono::steady_clock::now();
      {
        py::gil_scoped_release release;
        sim_.advance(seconds, std::ref(signals));
      }
      ++generation_;
      w[k] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      signals.rethrow();
    }
    return out;
  }

  // One step of dt (default: the scene's fixed step, else the auto step at
  // the current critical step): advance(dt) covers it with one step unless
  // stability asks for more.
  py::dict step(std::optional<double> dt) {
    const Busy busy(mutex_);
    const double fixed = scene_.spec.integrator.dt;
    const double d = dt ? *dt : fixed > 0 ? fixed : scene_.spec.integrator.safety * sim_.compute_critical_dt();
    return advance(d);
  }

  py::array positions() {
    const Busy busy(mutex_);
    return positions_.view(generation_, [&](std::vector<double>& x) { sim_.copy_positions(x); });
  }
  py::array displacements() {
    const Busy busy(mutex_);
    return displacements_.view(generation_, [&](std::vector<double>& u) { sim_.copy_displacement(u); });
  }
  py::array velocities() {
    const Busy busy(mutex_);
    return velocities_.view(generation_, [&](std::vector<double>& v) { sim_.copy_velocity(v); });
  }
  py::array rest_positions(py::object self) {
    static_assert(sizeof(Vec3) == 3 * sizeof(double));
    const std::vector<Vec3>& X = sim_.mesh().X;
    return view(&X.data()->x, X.size(), 3, self);
  }
  py::array tets(py::object self) {
    py::array a(py::dtype::of<int32_t>(), {tets_.size() / per_tet_, per_tet_},
                {per_tet_ * sizeof(int32_t), sizeof(int32_t)}, tets_.data(), self);
    a.attr("setflags")(py::arg("write") = false);
    return a;
  }

  // Per proxy or device: (n, 3) arrays of what each felt in the latest step
  // and the mean over the steps since clear_impulses().
  // (The caller holds the lock: sim()->proxy_reports().)
  template <class Report>
  py::dict reports(const std::vector<Report>& rs, const std::vector<ImpulseMark>& over_advance) const {
    py::array_t<double> force({rs.size(), size_t(3)}), torque({rs.size(), size_t(3)}),
        step_force({rs.size(), size_t(3)}), step_torque({rs.size(), size_t(3)}), mean_force({rs.size(), size_t(3)}),
        mean_torque({rs.size(), size_t(3)});
    py::array_t<int32_t> contacts(rs.size());
    auto f = force.mutable_unchecked<2>(), t = torque.mutable_unchecked<2>(), sf = step_force.mutable_unchecked<2>(),
         st = step_torque.mutable_unchecked<2>(), mf = mean_force.mutable_unchecked<2>(),
         mt = mean_torque.mutable_unchecked<2>();
    auto c = contacts.mutable_unchecked<1>();
    for (size_t k = 0; k < rs.size(); ++k) {
      const Report& r = rs[k];
      const bool advanced = k < over_advance.size();
      for (int d = 0; d < 3; ++d) {
        f(k, d) = advanced ? over_advance[k].impulse[d] : 0.0;
        t(k, d) = advanced ? over_advance[k].angular_impulse[d] : 0.0;
        sf(k, d) = r.force[d];
        st(k, d) = r.torque[d];
        mf(k, d) = r.elapsed > 0 ? r.impulse[d] / r.elapsed : 0.0;
        mt(k, d) = r.elapsed > 0 ? r.angular_impulse[d] / r.elapsed : 0.0;
      }
      c(k) = r.contacts;
    }
    py::dict out;
    out["force"] = force;
    out["torque"] = torque;
    out["step_force"] = step_force;
    out["step_torque"] = step_torque;
    out["mean_force"] = mean_force;
    out["mean_torque"] = mean_torque;
    out["contacts"] = contacts;
    return out;
  }
  py::dict locked_reports(bool proxies) {
    const Busy busy(mutex_);
    return proxies ? reports(sim_.proxy_reports(), proxy_means_) : reports(sim_.device_reports(), device_means_);
  }

  template <class Report>
  static std::vector<ImpulseMark> marks(const std::vector<Report>& rs) {
    std::vector<ImpulseMark> out;
    for (const Report& r : rs) out.push_back({r.impulse, r.angular_impulse, r.elapsed});
    return out;
  }
  template <class Report>
  static std::vector<ImpulseMark> means(const std::vector<ImpulseMark>& before, const std::vector<Report>& rs) {
    std::vector<ImpulseMark> out;
    for (size_t k = 0; k < rs.size(); ++k) {
      // (A clear_impulses() inside the span, from drive_scripts, leaves sums smaller than before: from zero then.)
      const ImpulseMark b = k < before.size() && rs[k].elapsed >= before[k].elapsed ? before[k] : ImpulseMark{};
      const double span = rs[k].elapsed - b.elapsed;
      out.push_back(span > 0 ? ImpulseMark{(rs[k].impulse - b.impulse) / span,
                                           (rs[k].angular_impulse - b.angular_impulse) / span, span}
                             : ImpulseMark{});
    }
    return out;
  }

  void set_proxy_motion(int32_t proxy, const PoseTuple& from, const PoseTuple& to, double t0, double t1) {
    const Busy busy(mutex_);
    check_index("proxy", proxy, sim_.proxies().size());
    proxy_taken_[size_t(proxy)] = true;
    sim_.set_proxy_motion(proxy, motion(from, to, t0, t1));
  }
  void set_hand_motion(int32_t hand, const PoseTuple& from, const PoseTuple& to, double t0, double t1) {
    const Busy busy(mutex_);
    check_index("hand", hand, sim_.hands().size());
    hand_taken_[size_t(hand)] = true;
    sim_.set_hand_motion(hand, motion(from, to, t0, t1));
  }
  // Glides proxy `proxy` from where it is now to `position` (and
  // `orientation`) over the next `duration` seconds.
  void move_proxy(int32_t proxy, const std::array<double, 3>& position,
                  const std::optional<std::array<double, 4>>& orientation, double duration) {
    const Busy busy(mutex_);
    check_index("proxy", proxy, sim_.proxies().size());
    if (!(duration > 0) || !std::isfinite(duration)) throw py::value_error("duration: must be finite and > 0");
    const Pose from = sim_.proxy_pose(proxy);
    Pose to = to_pose(position, orientation);
    if (!orientation) to.orientation = from.orientation;
    proxy_taken_[size_t(proxy)] = true;
    sim_.set_proxy_motion(proxy, ProxyMotion{sim_.time(), sim_.time() + duration, from, to});
  }
  // The scene's scripted motions over [t0, t1], as a headless run sets them
  // before each control interval, and the impulse sums started again.
  void drive_scripts(double t0, double t1) {
    const Busy busy(mutex_);
    for (size_t j = 0; j < scene_.proxy_script.size(); ++j)
      if (scene_.proxy_script[j]) sim_.set_proxy_motion(int32_t(j), scene_.proxy_script[j]->motion(t0, t1));
    for (size_t h = 0; h < scene_.hand_script.size(); ++h)
      if (scene_.hand_script[h]) sim_.set_hand_motion(int32_t(h), scene_.hand_script[h]->motion(t0, t1));
    sim_.clear_impulses();
  }

  // A parameter by the live server's name (scene/parameters.hpp: material.E,
  // damping.alpha, gravity.y, friction.mu, ...): the model is rebuilt with it
  // and the body goes on from where it is, as the live server's SetParameter
  // carries it. Raises SceneError naming the parameter (an unknown name, a
  // value out of its range).
  void set_parameter(const std::string& name, double value) {
    const Busy busy(mutex_);
    ModelSpec spec = scene_.spec;
    apply_parameter(spec, name, value);
    Simulation next(spec);
    next.track_contact_forces(true);
    next.continue_from(sim_);
    sim_ = std::move(next);
    scene_.spec = std::move(spec);
    ++generation_;
  }
  py::list parameters() {
    const Busy busy(mutex_);
    py::list out;
    for (const Parameter& p : list_parameters(scene_.spec)) {
      py::dict d;
      d["name"] = p.name;
      d["value"] = p.value;
      d["min"] = p.min;
      d["max"] = p.max;
      d["unit"] = p.unit;
      out.append(d);
    }
    return out;
  }

  // Whether a script is left to play: a scripted proxy or hand not moved from Python.
  bool scripted() const {
    for (size_t j = 0; j < scene_.proxy_script.size(); ++j)
      if (scene_.proxy_script[j] && !proxy_taken_[j]) return true;
    for (size_t h = 0; h < scene_.hand_script.size(); ++h)
      if (scene_.hand_script[h] && !hand_taken_[h]) return true;
    return false;
  }
  // The scripts over [t0, t1], but of the proxies and hands Python moved.
  void drive(double t0, double t1) {
    for (size_t j = 0; j < scene_.proxy_script.size(); ++j)
      if (scene_.proxy_script[j] && !proxy_taken_[j])
        sim_.set_proxy_motion(int32_t(j), scene_.proxy_script[j]->motion(t0, t1));
    for (size_t h = 0; h < scene_.hand_script.size(); ++h)
      if (scene_.hand_script[h] && !hand_taken_[h])
        sim_.set_hand_motion(int32_t(h), scene_.hand_script[h]->motion(t0, t1));
  }

  void write_vtu(const std::string& path, const std::vector<std::string>& cell_fields) {
    const Busy busy(mutex_);
    ElementFieldRequest ask;
    bool contact = false;
    for (const std::string& f : cell_fields) {
      if (f == "cauchy_stress")
        ask.cauchy_stress = true;
      else if (f == "green_strain")
        ask.green_strain = true;
      else if (f == "von_mises")
        ask.von_mises = true;
      else if (f == "principal_stretches")
        ask.principal_stretches = true;
      else if (f == "contact_force")
        contact = true;
      else
        throw py::value_error(
            "fields: must be cauchy_stress, green_strain, von_mises, principal_stretches or contact_force (the "
            "scene's run.vtu_fields), got " +
            f);
    }
    std::vector<double> u, v, density = sim_.compute_element_energy();
    sim_.copy_displacement(u);
    sim_.copy_velocity(v);
    for (size_t t = 0; t < density.size(); ++t) density[t] /= sim_.tet_volume()[t];
    const std::vector<uint8_t> fixed = sim_.node_constraint();
    const ElementFields fields = sim_.compute_element_fields(ask);
    std::vector<double> force;
    if (contact) {  // the mean over what was advanced since the previous write that asked for it
      const double span = sim_.take_contact_impulses(force);
      for (double& x : force) x = span > 0 ? x / span : 0.0;
    }
    tactile::write_vtu(path, VtuFrame{&sim_.mesh(), &u, &v, &fixed, contact ? &force : nullptr, &density, &fields});
  }

  Locked sim() { return Locked(mutex_, sim_); }
  const Scene& scene() const { return scene_; }

 private:
  static void check_index(const char* what, int32_t i, size_t n) {
    if (i < 0 || size_t(i) >= n)
      throw py::index_error(std::string(what) + " " + std::to_string(i) + ": the scene has " + std::to_string(n));
  }
  static ProxyMotion motion(const PoseTuple& from, const PoseTuple& to, double t0, double t1) {
    if (!(t1 > t0) || !std::isfinite(t0) || !std::isfinite(t1)) throw py::value_error("t1 must be finite and > t0");
    return ProxyMotion{t0, t1, to_pose(from.first, from.second), to_pose(to.first, to.second)};
  }

  std::recursive_mutex mutex_;  // held by every call on sim_ (Busy)
  Scene scene_;
  Simulation sim_;
  Published positions_, displacements_, velocities_;     // mesh order (n_nodes x 3)
  uint64_t generation_ = 0;                              // advance() calls so far: a view's array is of one
  std::vector<int32_t> tets_;                            // (n_tets x per_tet_)
  size_t per_tet_ = 4;                                   // 10 for quadratic tets (corners, then edge nodes)
  std::vector<bool> proxy_taken_, hand_taken_;           // moved from Python: their scripts no longer play
  std::vector<ImpulseMark> proxy_means_, device_means_;  // over the latest advance()
};

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// The module's exceptions: SceneError, ModelError and RecordingError, each a
// ValueError, and the C++ exceptions they translate.
void bind_errors(py::module_& m) {
  static py::exception<SceneError> scene_error(m, "SceneError", PyExc_ValueError);
  static py::exception<ModelError> model_error(m, "ModelError", PyExc_ValueError);
  static py::exception<ResimError> recording_error(m, "RecordingError", PyExc_ValueError);
  // PyErr_SetString rather than py::set_error (pybind11 2.12): the batch image builds against Debian 12's 2.10.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const SceneError& e) {
      PyErr_SetString(scene_error.ptr(), e.what());
    } catch (const MeshError& e) {
      PyErr_SetString(scene_error.ptr(), e.what());
    } catch (const ModelError& e) {
      PyErr_SetString(model_error.ptr(), e.what());
    } catch (const ResimError& e) {
      PyErr_SetString(recording_error.ptr(), e.what());
    } catch (const mcap::McapError& e) {
      PyErr_SetString(recording_error.ptr(), e.what());
    }
  });
}

// Scene, load_scene and parse_scene: the CLIs' loader.
void bind_scene(py::module_& m) {
  py::class_<Scene>(m, "Scene", "A scene as the loader checked it (one variant).")
      .def_readonly("name", &Scene::name, "the scene's name (its file's \"name\")")
      .def_readonly("variant", &Scene::variant, "the variant this Scene is, \"\" for a scene without variants")
      .def_readonly("path", &Scene::path, "the scene file, as given (relative mesh paths are read from its folder)")
      .def_property_readonly(
          "duration", [](const Scene& s) { return s.run.duration; }, "run.duration: what tactile-sim run simulates [s]")
      .def_property_readonly(
          "frame_rate", [](const Scene& s) { return s.run.frame_rate; },
          "run.frame_rate: frames a second of simulated time [Hz]")
      .def_property_readonly(
          "n_nodes", [](const Scene& s) { return s.spec.mesh.n_nodes(); }, "nodes of the mesh (every body's)")
      .def_property_readonly(
          "n_tets", [](const Scene& s) { return int32_t(s.spec.mesh.tets.size()); }, "tets of the mesh (every body's)")
      .def_property_readonly(
          "bodies",
          [](const Scene& s) {
            if (!s.spec.bodies.empty()) return bodies_list(s.spec.bodies);
            const int32_t fine = s.spec.surface ? s.spec.surface->n_vertices() : 0;
            const auto fine_tris = int32_t(s.spec.surface ? s.spec.surface->rest.triangles.size() : 0);
            return bodies_list(
                {BodySpec{"body", 0, s.spec.mesh.n_nodes(), 0, s.spec.mesh.n_tets(), 0, fine, 0, fine_tris}});
          },
          "the bodies (one for a scene of one): dicts of name, and slices nodes, tets, fine_vertices, "
          "fine_triangles into the arrays a Simulation gives (a body's node i is nodes.start + i)")
      .def_property_readonly(
          "proxies",
          [](const Scene& s) {
            std::vector<std::string> out;
            for (const ProxySpec& p : s.spec.proxies) out.push_back(p.name);
            return out;
          },
          "the proxies' names, in the order of a Simulation's per-proxy arrays")
      .def_property_readonly(
          "tracked",
          [](const Scene& s) {
            std::vector<std::pair<std::string, int32_t>> out;
            for (const TrackedPoint& p : s.track) out.emplace_back(p.name, p.node);
            return out;
          },
          "the scene's tracked points: (name, node), the node nearest each (index into the node arrays)")
      .def_property_readonly(
          "scripted",
          [](const Scene& s) {
            for (const auto& p : s.proxy_script)
              if (p) return true;
            for (const auto& h : s.hand_script)
              if (h) return true;
            return false;
          },
          "whether a proxy or hand of the scene follows a script (Simulation.advance() plays them)")
      // A Scene pickles as its JSON, its path and its variant, and is parsed
      // again where it is unpickled (its mesh files, if any, read there).
      .def(py::pickle([](const Scene& s) { return py::make_tuple(s.source, s.path, s.variant); },
                      [](const py::tuple& t) {
                        if (t.size() != 3) throw std::runtime_error("a pickled Scene is (source, path, variant)");
                        const auto path = t[1].cast<std::string>(), variant = t[2].cast<std::string>();
                        std::vector<Scene> one =
                            pick(parse_scene(nlohmann::json::parse(t[0].cast<std::string>()), path),
                                 variant.empty() ? std::nullopt : std::optional<std::string>(variant), path);
                        return std::move(one.front());
                      }));

  m.def(
      "load_scene",
      [](const std::string& path, std::optional<std::string> variant) { return pick(load_scene(path), variant, path); },
      py::arg("path"), py::arg("variant") = py::none(),
      "Reads and checks a scene file: one Scene per variant (the named one only with `variant`). Raises SceneError "
      "naming the file and the field at fault.");
  m.def(
      "parse_scene",
      [](const std::string& text, const std::string& path, std::optional<std::string> variant) {
        nlohmann::json j;
        try {
          j = nlohmann::json::parse(text);
        } catch (const nlohmann::json::parse_error& e) {
          throw SceneError(path + ": not JSON: " + e.what());
        }
        return pick(parse_scene(j, path), variant, path);
      },
      py::arg("text"), py::arg("path"), py::arg("variant") = py::none(),
      "The same from JSON text; `path` names the scene in messages and anchors relative mesh paths.");
}

// Whole runs as the CLIs make them: run_headless, resimulate.
void bind_runs(py::module_& m) {
  m.def(
      "run_headless",
      [](const Scene& scene, const std::string& out_dir, bool vtu) {
        HeadlessOptions h;
        h.out_dir = out_dir;
        h.write_vtu = vtu;
        h.progress = false;
        HeadlessResult r;
        {
          py::gil_scoped_release release;
          r = run_headless(scene, h);
        }
        return r.dir;
      },
      py::arg("scene"), py::arg("out_dir"), py::arg("vtu") = false,
      "Runs the scene headless as `tactile-sim run` does (the same code), writing OUT_DIR/<scene>/<variant or "
      "run>/ (summary.json, frames.csv, and VTU frames with vtu=True); returns that folder. A fault ends the run "
      "and is in summary.json; a spec the core refuses raises ModelError.");

  m.def(
      "resimulate",
      [](const std::string& recording, const std::string& scene, const std::string& scene_text,
         const std::string& variant, const std::string& out) {
        ResimOptions o;
        o.recording = recording;
        o.scene = scene;
        o.scene_text = scene_text;
        o.variant = variant;
        o.out = out;
        ResimReport r;
        {
          py::gil_scoped_release release;
          r = resimulate(o);
        }
        py::dict d;
        d["scene_name"] = r.scene_name;
        d["steps"] = r.steps;
        d["inputs"] = r.inputs;
        d["states"] = r.states;
        d["states_matched"] = r.states_matched;
        d["states_identical"] = r.states_identical;
        d["haptic"] = r.haptic;
        d["haptic_matched"] = r.haptic_matched;
        d["haptic_identical"] = r.haptic_identical;
        d["max_position_difference_m"] = r.max_position_difference;
        d["max_force_difference_N"] = r.max_force_difference;
        d["first_difference_time_s"] = r.first_difference_time;
        d["peak_force_N"] = r.peak_force;
        d["recorded_peak_force_N"] = r.recorded_peak_force;
        d["note"] = r.note;
        return d;
      },
      py::arg("recording"), py::arg("scene") = "", py::arg("scene_text") = "", py::arg("variant") = "",
      py::arg("out") = "",
      "Feeds a recording's device inputs to the simulator again, as `tactile-sim resim` does (the same code): on "
      "the recorded scene, or on `scene` (a file; with `scene_text`, that JSON instead of the file's, `scene` "
      "anchoring its paths). Returns the report as a dict; with `out`, writes the re-simulation as a recording. "
      "Raises RecordingError naming what is wrong with the recording.");
}

// The accuracy study and the stability suite one case at a time, for tactile-batch.
void bind_studies(py::module_& m) {
  // The accuracy-cost study one run at a time (study/accuracy.hpp), for tactile-batch.
  m.def(
      "accuracy_cases",
      [](bool quick, const std::string& only) {
        study::AccuracyOptions o;
        o.quick = quick;
        o.only = only;
        py::list out;
        for (const study::AccuracyCase& c : study::list_accuracy_cases(o)) {
          py::dict d;
          d["label"] = c.label;
          d["problem"] = c.problem;
          d["material"] = c.material;
          d["element"] = c.element;
          d["level"] = c.level;
          d["precision"] = c.precision;
          d["safety"] = c.safety;
          d["quick"] = c.quick;
          out.append(d);
        }
        return out;
      },
      py::arg("quick") = false, py::arg("only") = "",
      "The accuracy study's runs (as dicts), in the order tactile-accuracy runs them.");
  m.def(
      "run_accuracy_case",
      [](const py::dict& d, const std::string& scenes) {
        study::AccuracyCase c;
        c.label = d["label"].cast<std::string>();
        c.problem = d["problem"].cast<std::string>();
        c.material = d["material"].cast<std::string>();
        if (d.contains("element")) c.element = d["element"].cast<std::string>();
        c.level = d["level"].cast<int32_t>();
        c.precision = d["precision"].cast<std::string>();
        c.safety = d["safety"].cast<double>();
        c.quick = d["quick"].cast<bool>();
        py::gil_scoped_release release;
        return study::accuracy_json(study::run_accuracy_case(c, scenes), c.quick);
      },
      py::arg("case"), py::arg("scenes"), "One run of the study; its results as JSON.");
  m.def(
      "finish_accuracy",
      [](const std::vector<std::string>& parts, bool quick) {
        study::AccuracyResults all;
        for (const std::string& text : parts) {
          study::AccuracyResults one = study::accuracy_from_json(text);
          all.records.insert(all.records.end(), one.records.begin(), one.records.end());
          all.realtime.insert(all.realtime.end(), one.realtime.begin(), one.realtime.end());
        }
        study::finish_accuracy(all);
        return study::accuracy_json(all, quick);
      },
      py::arg("parts"), py::arg("quick"),
      "The study's accuracy.json (as tactile-accuracy writes it) from its runs' results, in list order.");

  // The stability suite one case at a time (study/stability.hpp), for tactile-batch.
  m.def(
      "stability_cases",
      [](bool quick, const std::string& only, uint64_t seed) {
        study::SuiteOptions o;
        o.quick = quick;
        o.filter = only;
        o.seed = seed;
        std::vector<std::string> names;
        for (const study::StabilityCase& c : study::stability_cases(o)) names.push_back(c.name);
        return names;
      },
      py::arg("quick") = false, py::arg("only") = "", py::arg("seed") = 1,
      "The suite's case names (group/material/mesh), in tactile-stability's order; `only` keeps those containing it.");
  m.def(
      "run_stability_case",
      [](const std::string& name, bool quick, uint64_t seed) {
        study::SuiteOptions o;
        o.quick = quick;
        o.seed = seed;
        py::gil_scoped_release release;
        return study::outcome_json(study::run_stability_case(o, name));
      },
      py::arg("name"), py::arg("quick") = false, py::arg("seed") = 1,
      "One case, run; its outcome as JSON (an entry of tactile-stability --json).");
}

// Simulation: one body in motion, stepped and read from Python.
void bind_simulation(py::module_& m) {
  py::class_<PySimulation>(m, "Simulation", "One body in motion: a scene's model, stepper and state.")
      .def(py::init<const Scene&>(), py::arg("scene"))
      .def("advance", &PySimulation::advance, py::arg("seconds"), py::arg("scripts") = true,
           "Covers `seconds` [s] with as many steps as stability needs; returns the report (substeps, dt [s], "
           "dt_critical [s], subdivided, fault). With `scripts` (the default) the scene's scripted proxies and "
           "hands follow their scripts, those moved from Python (move_proxy, set_proxy_motion, set_hand_motion) "
           "excepted, in control intervals of at most 1 ms as tactile-sim run drives them; scripts=False leaves "
           "every proxy to Python. proxy_reports['force'] is then the mean over this call. Another thread's call "
           "on this Simulation waits for it; Ctrl-C (KeyboardInterrupt) stops it between two steps, at the time "
           "reached.")
      .def("step", &PySimulation::step, py::arg("dt") = py::none(),
           "One step of dt [s] (default: the scene's fixed step, else safety x the current critical step).")
      .def("time_advance", &PySimulation::time_advance, py::arg("seconds"), py::arg("count"),
           "advance(seconds) `count` times in a loop in C++; the wall time of each call [s] (a benchmark's "
           "reference for the same loop from Python).")
      .def_property_readonly(
          "time", [](PySimulation& s) { return s.sim()->time(); }, "simulated time since the start [s]")
      .def_property_readonly(
          "steps", [](PySimulation& s) { return s.sim()->steps(); }, "steps taken since the start")
      .def_property_readonly(
          "n_nodes", [](PySimulation& s) { return s.sim()->n_nodes(); }, "nodes (the rows of the node arrays)")
      .def_property_readonly(
          "n_tets", [](PySimulation& s) { return s.sim()->n_tets(); }, "tets (the rows of tets and the cell arrays)")
      .def_property_readonly(
          "dt_rest", [](PySimulation& s) { return s.sim()->dt_rest(); },
          "the critical step of the mesh at rest [s] (what \"dt\": \"auto\" starts from)")
      .def_property_readonly(
          "bodies",
          [](PySimulation& s) {
            std::vector<BodySpec> specs;
            for (const ModelBody& b : s.sim()->bodies()) specs.push_back(b.spec);
            return bodies_list(specs);
          },
          "the bodies, as Scene.bodies: dicts of name and slices nodes, tets, fine_vertices, fine_triangles; "
          "e.g. sim.displacements[b['nodes']] is body b's own displacement, in its own node order")
      .def_property_readonly(
          "precision", [](PySimulation& s) { return s.sim()->precision() == Precision::Float ? "float" : "double"; },
          "the arithmetic the core steps in: \"float\" or \"double\" (integrator.precision)")
      .def(
          "critical_dt", [](PySimulation& s) { return s.sim()->compute_critical_dt(); },
          "the critical step of the body as it is now [s]: a step above it is unstable")
      .def_property_readonly(
          "positions", &PySimulation::positions,
          "X + u [m] (n_nodes x 3) now: a read-only view that never changes (read it again after advance())")
      .def_property_readonly(
          "displacements", &PySimulation::displacements,
          "u [m] (n_nodes x 3) now: a read-only view that never changes (read it again after advance())")
      .def_property_readonly(
          "velocities", &PySimulation::velocities,
          "v [m/s] (n_nodes x 3) now: a read-only view that never changes (read it again after advance())")
      .def_property_readonly(
          "rest_positions", [](py::object self) { return self.cast<PySimulation&>().rest_positions(self); },
          "X [m] (n_nodes x 3), read-only")
      .def_property_readonly(
          "tets", [](py::object self) { return self.cast<PySimulation&>().tets(self); },
          "node ids of each tet (n_tets x 4; quadratic tets n_tets x 10: corners, then edge nodes in VTK's order), "
          "read-only")
      .def_property_readonly(
          "energy", [](PySimulation& s) { return energy_dict(s.sim()->energy()); },
          "the energy balance's terms as of the latest step [J]: kinetic, elastic, gravity, work_loads, "
          "work_essential, work_contact, dissipated, discrete, restated (server/scenes/README.md: the balance)")
      .def(
          "compute_energy", [](PySimulation& s) { return energy_dict(s.sim()->compute_energy()); },
          "the same terms, computed afresh from the state now [J]")
      .def_property_readonly(
          "fault", [](PySimulation& s) { return fault_object(s.sim()->fault()); },
          "None, or what stopped the simulation (kind, message, time [s], step, and the elements or nodes at "
          "fault); advance() does nothing more after one")
      .def(
          "element_energy",
          [](PySimulation& s) {
            const std::vector<double> e = s.sim()->compute_element_energy();
            return py::array_t<double>(py::ssize_t(e.size()), e.data());
          },
          "each tet's elastic energy now, V psi(F) [J] (n_tets,)")
      .def(
          "element_fields",
          [](PySimulation& s, bool cauchy_stress, bool green_strain, bool von_mises) {
            const ElementFields f = s.sim()->compute_element_fields({cauchy_stress, green_strain, von_mises});
            py::dict out;
            const auto n = size_t(s.sim()->n_tets());
            if (cauchy_stress)
              out["cauchy_stress"] = py::array_t<double>({n, size_t(3), size_t(3)}, f.cauchy_stress.data());
            if (green_strain)
              out["green_strain"] = py::array_t<double>({n, size_t(3), size_t(3)}, f.green_strain.data());
            if (von_mises) out["von_mises"] = py::array_t<double>(py::ssize_t(n), f.von_mises.data());
            return out;
          },
          py::arg("cauchy_stress") = false, py::arg("green_strain") = false, py::arg("von_mises") = false,
          "per tet, the fields asked for: cauchy_stress [Pa] and green_strain [1] (n_tets, 3, 3), von_mises [Pa] "
          "(n_tets,)")
      .def_property_readonly(
          "proxy_names",
          [](PySimulation& s) {
            std::vector<std::string> out;
            for (const ProxySpec& p : s.sim()->proxies()) out.push_back(p.name);
            return out;
          },
          "the proxies' names, in the order of every per-proxy array")
      .def_property_readonly(
          "devices", [](PySimulation& s) { return s.sim()->devices(); },
          "the device channels' names, in the order of device_reports")
      .def_property_readonly(
          "proxy_reports", [](PySimulation& s) { return s.locked_reports(true); },
          "per proxy, (n_proxies, 3) arrays: force [N] and torque [N m] on it, their mean over the latest "
          "advance() (what a device would be sent); step_force, step_torque: the latest step's alone (a "
          "contact pushes every other step or so, so it chatters); mean_force, mean_torque: over every step "
          "since clear_impulses(); and contacts (n_proxies,), the latest step's contact points")
      .def_property_readonly(
          "device_reports", [](PySimulation& s) { return s.locked_reports(false); },
          "per device channel, as proxy_reports: for a coupled device the coupling's force on the device")
      // The report dict is a temporary: take the array out of it as an
      // object before it dies (an item accessor would outlive its dict).
      .def_property_readonly(
          "proxy_forces", [](PySimulation& s) -> py::object { return s.locked_reports(true)["force"]; },
          "proxy_reports['force']: each proxy's mean force over the latest advance() [N] (n_proxies, 3)")
      .def(
          "clear_impulses", [](PySimulation& s) { s.sim()->clear_impulses(); },
          "starts the reports' mean_force and mean_torque again from now")
      .def(
          "proxy_pose", [](PySimulation& s, int32_t j) { return from_pose(s.sim()->proxy_pose(j)); }, py::arg("proxy"),
          "the proxy's pose now: (position [m], orientation as a quaternion (w, x, y, z))")
      .def(
          "hand_pose", [](PySimulation& s, int32_t h) { return from_pose(s.sim()->hand_pose(h)); }, py::arg("hand"),
          "the hand's pose now, as proxy_pose")
      .def("set_proxy_motion", &PySimulation::set_proxy_motion, py::arg("proxy"), py::arg("pose_from"),
           py::arg("pose_to"), py::arg("t0"), py::arg("t1"),
           "Moves the proxy from pose_from to pose_to (each (position [m], quaternion (w, x, y, z))) over simulated "
           "time [t0, t1] [s]; it leaves its script, if it has one.")
      .def("set_hand_motion", &PySimulation::set_hand_motion, py::arg("hand"), py::arg("pose_from"), py::arg("pose_to"),
           py::arg("t0"), py::arg("t1"), "As set_proxy_motion, for a hand.")
      .def("move_proxy", &PySimulation::move_proxy, py::arg("proxy"), py::arg("position"),
           py::arg("orientation") = py::none(), py::kw_only(), py::arg("duration"),
           "Glides the proxy from where it is to `position` (and `orientation`) over the next `duration` seconds.")
      .def("drive_scripts", &PySimulation::drive_scripts, py::arg("t0"), py::arg("t1"),
           "Sets every scripted proxy's and hand's motion over [t0, t1] [s] from its script, and clears the "
           "impulses (what advance() does itself; for a loop that steps with advance(..., scripts=False)).")
      .def(
          "couple_device",
          [](PySimulation& s, int32_t device, std::optional<std::array<double, 3>> limits) {
            if (device < 0 || size_t(device) >= s.sim()->devices().size())
              throw py::index_error("device " + std::to_string(device) + ": the scene has " +
                                    std::to_string(s.sim()->devices().size()));
            if (!limits) return s.sim()->couple_device(device, nullptr);
            const DeviceLimits l{(*limits)[0], (*limits)[1], (*limits)[2]};
            s.sim()->couple_device(device, &l);
          },
          py::arg("device"), py::arg("limits") = py::none(),
          "Couples a device channel's proxies (limits: max force [N], max torque [N m], stiffness [N/m]).")
      .def(
          "release_device",
          [](PySimulation& s, int32_t device) {
            if (device < 0 || size_t(device) >= s.sim()->devices().size())
              throw py::index_error("device " + std::to_string(device) + ": the scene has " +
                                    std::to_string(s.sim()->devices().size()));
            s.sim()->release_device(device);
          },
          py::arg("device"), "Uncouples a device channel: its proxies move as scripted or set again.")
      .def("set_parameter", &PySimulation::set_parameter, py::arg("name"), py::arg("value"),
           "Sets a parameter by the live server's name (material.E [Pa], material.nu, material.rho [kg/m^3], "
           "damping.alpha [1/s], gravity.x|y|z [m/s^2], friction.mu, effects.damping ...; `parameters` lists this "
           "scene's with their ranges): the model is rebuilt with it and the body goes on from where it is. Raises "
           "SceneError naming the parameter when the name is unknown or the value out of its range.")
      .def_property_readonly("parameters", &PySimulation::parameters,
                             "the parameters set_parameter takes for this scene: dicts of name, value, min, max, unit")
      .def("write_vtu", &PySimulation::write_vtu, py::arg("path"), py::arg("fields") = std::vector<std::string>{},
           "Writes the body as it is now (VTK XML, .vtu): displacement, velocity, constraint and energy density, and "
           "the fields named, those a scene's run.vtu_fields takes: cauchy_stress [Pa], green_strain [1], "
           "von_mises [Pa], principal_stretches [1] (per tet), contact_force [N] (per node: the mean over what "
           "was advanced since the previous write_vtu that asked for it, or since the start).");
}

}  // namespace
}  // namespace tactile

PYBIND11_MODULE(_core, m) {
  using namespace tactile;
  m.doc() = "The tactile simulation core: scenes, simulations and their arrays (see the tactile package).";
  m.attr("__version__") = kVersion;  // (VERSION, through CMake)
  bind_errors(m);
  bind_scene(m);
  bind_runs(m);
  bind_studies(m);
  bind_simulation(m);
}

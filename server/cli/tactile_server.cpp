// tactile-server: runs a scene live, paced to real time, and serves it over
// WebSocket (the protocol in proto/tactile.fbs) and static files over HTTP on
// the same port.
//
// Exit codes: 0 stopped by a signal, 1 a fault stopped the simulation, 2 bad
// input (scene, mesh, command line, or an address it may not listen on).
#include <sys/resource.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>

#include "app/command_line.hpp"
#include "app/progress.hpp"
#include "core/model.hpp"
#include "live/director.hpp"
#include "mesh/mesh_error.hpp"
#include "net/server.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"

namespace {

using namespace tactile;

// Sets the process's nice value, and, where the kernel groups the CPU by
// session (autogroup, sched(7)), its session group's: there a nice value
// ranks threads only within their session, and a browser started from another
// session shares the CPU with ours as an equal group whatever our threads'
// nice (Playwright's Chromium does: client-web/bench/round_trip.mjs). The
// group's nice is lowered, never raised; a refusal is said, not fatal.
void set_priority(int nice) {
  if (setpriority(PRIO_PROCESS, 0, nice) != 0)
    std::printf("tactile-server: nice %d refused (%s): running at normal priority\n", nice, std::strerror(errno));
  std::ifstream enabled("/proc/sys/kernel/sched_autogroup_enabled");
  int on = 0;
  if (nice >= 0 || !(enabled >> on) || on != 1) return;
  std::ifstream group_in("/proc/self/autogroup");  // "/autogroup-155 nice 0"
  std::string name, word;
  int group_nice = 0;
  if (!(group_in >> name >> word >> group_nice) || group_nice <= nice) return;
  std::ofstream group_out("/proc/self/autogroup");
  group_out << nice << std::flush;
  if (!group_out)
    std::printf(
        "tactile-server: session group nice %d refused: the threads of other sessions (a browser) share "
        "the CPU with this one as equals\n",
        nice);
}

// Refusals after the command line is read (an unknown variant, a missing folder).
struct BadInput {
  std::string message;
};

struct Options {
  std::string scene;
  ServerOptions server;
  std::optional<double> dt, duration;
  double state_rate = 30;
  double haptic_rate = 0;
  double force_window = 1e-3;
  std::optional<std::string> variant;
  std::optional<std::string> scenes_dir;
  std::string replay;
  int nice = -10;
};

// The command line's options, bound to `o`.
void add_options(CLI::App& app, Options& o, std::string& on_fault) {
  app.description(
      "Runs the scene in real time and serves it: WebSocket clients (viewers, devices, a controller)\n"
      "and static files over HTTP, on one port. With --replay, serves a recording the same way, at its\n"
      "recorded pace (a controller may pause, resume, seek and change the speed).");
  app.footer("exit status: 0 stopped, 1 a fault stopped the simulation, 2 bad input");
  CLI::Option* scene = app.add_option("SCENE.json", o.scene, "the scene to run")->type_name("");
  app.add_option("--bind", o.server.bind, "listen address (off loopback a token is required)")
      ->type_name("ADDR")
      ->capture_default_str();
  app.add_option("--port", o.server.port, "port (0 picks a free one)")
      ->type_name("N")
      ->check(CLI::Range(0, 65535).description(""))
      ->capture_default_str();
  app.add_option("--token", o.server.token, "token devices and controllers must present")
      ->type_name("T")
      ->envname("TACTILE_TOKEN");
  app.add_option("--allow-origin", o.server.allowed_origins,
                 "also accept WebSockets from browser Origin O (repeatable)")
      ->type_name("O")
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  app.add_option("--static", o.server.static_dir, "serve DIR over HTTP (e.g. client-web)")->type_name("DIR");
  app.add_option("--scenes", o.scenes_dir, "scenes a controller may load (default: the scene file's folder)")
      ->type_name("DIR");
  app.add_option("--dt", o.dt, "simulation step, > 0 (default: the scene's fixed step, else 0.7 x critical at rest)")
      ->type_name("S")
      ->check(positive_number());
  app.add_option("--state-rate", o.state_rate, "state frames per second to viewers, > 0")
      ->type_name("HZ")
      ->check(positive_number())
      ->capture_default_str();
  app.add_option("--haptic-rate", o.haptic_rate,
                 "haptic frames per second to devices at most, > 0 (default: one after every step)")
      ->type_name("HZ")
      ->check(positive_number());
  app.add_option("--force-window", o.force_window,
                 "haptic forces are means over S, and over the frame interval at least; in (0, 0.1]")
      ->type_name("S")
      ->check(number_where([](double v) { return v > 0 && v <= 0.1; }, "in (0, 0.1] s"))
      ->capture_default_str();
  app.add_option("--variant", o.variant, "run this variant of the scene (default: the first)")->type_name("NAME");
  app.add_option("--duration", o.duration, "stop after S simulated seconds (default: run until stopped)")
      ->type_name("S")
      ->check(finite_number());
  app.add_option("--recordings", o.server.recordings_dir,
                 "where a controller's StartRecording writes (MCAP; default: none, refused)")
      ->type_name("DIR");
  app.add_option("--record", o.server.record, "record the session from the start into FILE (MCAP), until stopped")
      ->type_name("FILE");
  app.add_option("--record-compression", o.server.record_compression,
                 "how every recording's chunks are stored: zstd (the default) or none")
      ->transform(CLI::CheckedTransformer(std::map<std::string, mcap::Compression>{{"zstd", mcap::Compression::Zstd},
                                                                                   {"none", mcap::Compression::None}},
                                          CLI::ignore_case));
  CLI::Option* replay =
      app.add_option("--replay", o.replay,
                     "serve the recording FILE (MCAP) instead of a scene; it plays from the first client")
          ->type_name("FILE");
  app.add_option("--on-fault", on_fault,
                 "stop: a fault stops the simulation until a controller resets it;\n"
                 "reset: the server resets the scene itself, once its telemetry has named the fault")
      ->type_name("stop|reset")
      ->check(one_of({"stop", "reset"}))
      ->capture_default_str();
  app.add_option("--max-connections", o.server.max_connections, "WebSocket clients greeted at once, >= 1")
      ->type_name("N")
      ->check(CLI::Range(size_t(1), size_t(1) << 20).description(""))
      ->capture_default_str();
  app.add_option("--max-waiting", o.server.max_waiting,
                 "upgraded WebSockets not yet greeted, >= 1; when full, the oldest past its first second,\n"
                 "from the address holding the most, makes room (else the newcomer is refused)")
      ->type_name("N")
      ->check(CLI::Range(size_t(1), size_t(1) << 20).description(""))
      ->capture_default_str();
  app.add_option("--nice", o.nice,
                 "the server's nice value, -20 to 19: below 0 its simulation and network threads are served\n"
                 "before ordinary processes (a browser, a build) on a busy machine; where the system refuses\n"
                 "(no CAP_SYS_NICE) it runs at its normal priority and says so; below 0, where the kernel groups\n"
                 "the CPU by session (autogroup), its session's group is given it too")
      ->type_name("N")
      ->check(CLI::Range(-20, 19).description(""))
      ->capture_default_str();
  scene->excludes(replay);
  app.callback([&o] {
    if (o.scene.empty() && o.replay.empty()) throw CLI::RequiredError("a scene or --replay");
  });
}

std::atomic<bool> g_stop{false};

}  // namespace

// Serves a recording until a signal stops it.
int replay(const Options& o) {
  Replay replay(o.replay);
  boost::asio::io_context ioc(1);
  Server server(ioc, replay, o.server);
  std::printf("tactile-server: replaying %s: %zu messages over %.3f s\n", o.replay.c_str(), replay.items().size(),
              replay.duration());
  for (const std::string& p : replay.problems()) std::printf("tactile-server: %s: %s\n", o.replay.c_str(), p.c_str());
  std::printf("tactile-server: listening on http://%s:%u/ (WebSocket on the same port)\n", o.server.bind.c_str(),
              unsigned(server.port()));
  std::fflush(stdout);
  boost::asio::signal_set signals(ioc, SIGINT, SIGTERM);
  signals.async_wait([&](const boost::system::error_code& ec, int) {
    if (ec) return;
    server.stop();
    ioc.stop();
  });
  ioc.run();
  std::printf("tactile-server: stopped\n");
  return 0;
}

int main(int argc, char** argv) {
  // Whoever reads our output may be gone before we are: Ctrl-C in a terminal
  // stops `scripts/run.sh`'s tee with the server, whose last lines ("recording:
  // stopped") would then raise SIGPIPE and kill it before its recording is
  // closed. A write to a closed pipe fails instead (EPIPE), and the shutdown
  // goes on.
  std::signal(SIGPIPE, SIG_IGN);
  Options o;
  std::string on_fault = "stop";
  CLI::App app("", "tactile-server");
  configure_command_line(app);
  add_options(app, o, on_fault);
  if (const std::optional<int> status = parse_command_line(app, argc, argv)) return *status;
  o.server.reset_on_fault = on_fault == "reset";
  // Before any thread starts, so that every thread the server makes inherits it: a busy machine must not
  // slow the simulation a hand is coupled to (`bridge_bench.py loop --loaded` guards it).
  set_priority(o.nice);
  o.server.viewer_rate_hz = o.state_rate;
  try {
    if (!o.replay.empty()) return replay(o);
    tactile::MeshingProgress meshing(stderr, true);
    tactile::set_meshing_watch(&meshing);
    const std::vector<Scene> scenes = load_scene(o.scene);
    tactile::set_meshing_watch(nullptr);
    const Scene* scene = &scenes.front();
    if (o.variant) {
      scene = nullptr;
      for (const Scene& s : scenes)
        if (s.variant == *o.variant) scene = &s;
      if (!scene) throw BadInput{"scene has no variant '" + *o.variant + "'"};
    }
    LiveOptions live;
    live.dt = o.dt;
    live.state_rate_hz = o.state_rate;
    live.haptic_rate_hz = o.haptic_rate;
    live.force_window = o.force_window;
    auto first = std::make_shared<LiveScene>(*scene, 1, live);
    Director director(first);
    ServerOptions server_options = o.server;
    server_options.live = live;
    server_options.scenes_dir =
        o.scenes_dir ? *o.scenes_dir : std::filesystem::absolute(o.scene).parent_path().string();
    if (!std::filesystem::is_directory(server_options.scenes_dir))
      throw BadInput{"--scenes: not a folder: " + server_options.scenes_dir};

    boost::asio::io_context ioc(1);
    Server server(ioc, director, server_options);
    const Simulation& sim = first->sim();
    std::printf("tactile-server: scene %s%s, %d tets, %d nodes, step %g s, %zu proxies\n", scene->name.c_str(),
                scene->variant.empty() ? "" : ("/" + scene->variant).c_str(), sim.n_tets(), sim.n_nodes(),
                first->loop().dt(), sim.proxies().size());
    const double every = double(first->loop().haptic_every());
    std::printf("tactile-server: haptic frames every %g step%s (%.0f Hz), forces over %g ms\n", every,
                every == 1 ? "" : "s", 1.0 / (every * first->loop().dt()),
                1e3 * double(first->frames().force_window_steps()) * first->loop().dt());
    std::printf("tactile-server: listening on http://%s:%u/ (WebSocket on the same port)\n", o.server.bind.c_str(),
                unsigned(server.port()));
    std::fflush(stdout);

    std::thread simulation([&] {
      director.run(g_stop, o.duration.value_or(std::numeric_limits<double>::infinity()));
      boost::asio::post(ioc, [&] {
        server.stop();
        ioc.stop();
      });
    });
    boost::asio::signal_set signals(ioc, SIGINT, SIGTERM);
    signals.async_wait([&](const boost::system::error_code& ec, int) {
      if (!ec) g_stop = true;
    });
    ioc.run();
    g_stop = true;
    simulation.join();
    first.reset();
    const RealtimeStats st = director.current()->loop().stats();
    std::printf(
        "tactile-server: stopped after %.3f s simulated in %.3f s (real-time factor %.3f, %lld missed deadlines)\n",
        st.sim_time, st.wall_time, st.wall_time > 0 ? st.sim_time / st.wall_time : 0.0,
        static_cast<long long>(st.missed_deadlines));
    if (const std::string fault = director.fault(); !fault.empty()) {
      std::fprintf(stderr, "tactile-server: fault: %s\n", fault.c_str());
      return 1;
    }
    return 0;
  } catch (const BadInput& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.message.c_str());
    return 2;
  } catch (const SceneError& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.what());
    return 2;
  } catch (const ModelError& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.what());
    return 2;
  } catch (const MeshError& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.what());
    return 2;
  } catch (const ServerError& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.what());
    return 2;
  } catch (const mcap::McapError& e) {
    std::fprintf(stderr, "tactile-server: %s\n", e.what());
    return 2;
  }
}

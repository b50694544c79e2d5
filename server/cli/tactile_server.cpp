// tactile-server: runs a scene live, paced to real time, and serves it over
// WebSocket (the protocol in proto/tactile.fbs) and static files over HTTP on
// the same port.
//
// Exit codes: 0 stopped by a signal, 1 a fault stopped the simulation, 2 bad
// input (scene, mesh, command line, or an address it may not listen on).
#include <atomic>
#include <cmath>
#include <limits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>

#include "app/progress.hpp"
#include "app/simulation.hpp"
#include "core/model.hpp"
#include "live/director.hpp"
#include "mesh/mesh_error.hpp"
#include "net/server.hpp"
#include "scene/scene.hpp"

namespace {

using namespace tactile;

constexpr const char* kUsage =
    "usage: tactile-server SCENE.json [options]\n"
    "       tactile-server --replay RECORDING.mcap [options]\n"
    "\n"
    "Runs the scene in real time and serves it: WebSocket clients (viewers, devices, a controller)\n"
    "and static files over HTTP, on one port. With --replay, serves a recording the same way, at its\n"
    "recorded pace (a controller may pause, resume, seek and change the speed).\n"
    "\n"
    "options:\n"
    "  --bind ADDR          listen address (default 127.0.0.1; off loopback a token is required)\n"
    "  --port N             port (default 8765; 0 picks a free one)\n"
    "  --token T            token devices and controllers must present (default: $TACTILE_TOKEN)\n"
    "  --allow-origin O     also accept WebSockets from browser Origin O (repeatable)\n"
    "  --static DIR         serve DIR over HTTP (e.g. client-web)\n"
    "  --scenes DIR         scenes a controller may load (default: the scene file's folder)\n"
    "  --dt S               simulation step (default: the scene's fixed step, else 0.7 x critical at rest)\n"
    "  --state-rate HZ      state frames per second to viewers (default 30)\n"
    "  --haptic-rate HZ     haptic frames per second to devices at most (default: one after every step)\n"
    "  --force-window S     haptic forces are means over S, and over the frame interval at least (default 0.001)\n"
    "  --variant NAME       run this variant of the scene (default: the first)\n"
    "  --duration S         stop after S simulated seconds (default: run until stopped)\n"
    "  --recordings DIR     where a controller's StartRecording writes (MCAP; default: none, refused)\n"
    "  --record FILE        record the session from the start into FILE (MCAP), until stopped\n"
    "  --replay FILE        serve the recording FILE (MCAP) instead of a scene; it plays from the first client\n"
    "  --on-fault WHAT      stop: a fault stops the simulation until a controller resets it (default);\n"
    "                       reset: the server resets the scene itself, once its telemetry has named the fault\n"
    "\n"
    "exit status: 0 stopped, 1 a fault stopped the simulation, 2 bad input\n";

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
};

double number(std::string_view flag, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(v)) throw BadInput{std::string(flag) + ": not a number: " + text};
  return v;
}

Options parse_args(int argc, char** argv) {
  Options o;
  if (const char* t = std::getenv("TACTILE_TOKEN")) o.server.token = t;
  std::vector<std::string> args(argv + 1, argv + argc);
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> const std::string& {
      if (i + 1 >= args.size()) throw BadInput{a + " needs a value"};
      return args[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--bind") o.server.bind = value();
    else if (a == "--port") {
      const double p = number(a, value());
      if (p < 0 || p > 65535 || p != std::floor(p)) throw BadInput{"--port: not a port: " + args[i]};
      o.server.port = uint16_t(p);
    } else if (a == "--token") o.server.token = value();
    else if (a == "--allow-origin") o.server.allowed_origins.push_back(value());
    else if (a == "--static") o.server.static_dir = value();
    else if (a == "--scenes") o.scenes_dir = value();
    else if (a == "--dt") {
      o.dt = number(a, value());
      if (!(*o.dt > 0)) throw BadInput{"--dt must be > 0"};
    } else if (a == "--state-rate") {
      o.state_rate = number(a, value());
      if (!(o.state_rate > 0)) throw BadInput{"--state-rate must be > 0"};
    } else if (a == "--haptic-rate") {
      o.haptic_rate = number(a, value());
      if (!(o.haptic_rate > 0)) throw BadInput{"--haptic-rate must be > 0"};
    } else if (a == "--force-window") {
      o.force_window = number(a, value());
      if (!(o.force_window > 0 && o.force_window <= 0.1)) throw BadInput{"--force-window must be in (0, 0.1] s"};
    } else if (a == "--variant") o.variant = value();
    else if (a == "--duration") o.duration = number(a, value());
    else if (a == "--recordings") o.server.recordings_dir = value();
    else if (a == "--record") o.server.record = value();
    else if (a == "--replay") o.replay = value();
    else if (a == "--on-fault") {
      const std::string& w = value();
      if (w != "stop" && w != "reset") throw BadInput{"--on-fault: stop or reset, not " + w};
      o.server.reset_on_fault = w == "reset";
    }
    else if (!a.empty() && a[0] == '-') throw BadInput{"unknown option " + a};
    else if (o.scene.empty()) o.scene = a;
    else throw BadInput{"one scene only (got " + o.scene + " and " + a + ")"};
  }
  if (!o.replay.empty() && !o.scene.empty()) throw BadInput{"a scene or --replay, not both"};
  if (o.scene.empty() && o.replay.empty()) throw BadInput{"no scene given"};
  o.server.viewer_rate_hz = o.state_rate;
  return o;
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
  try {
    const Options o = parse_args(argc, argv);
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
    std::printf("tactile-server: stopped after %.3f s simulated in %.3f s (real-time factor %.3f, %lld missed deadlines)\n",
                st.sim_time, st.wall_time, st.wall_time > 0 ? st.sim_time / st.wall_time : 0.0,
                static_cast<long long>(st.missed_deadlines));
    if (const std::string fault = director.fault(); !fault.empty()) {
      std::fprintf(stderr, "tactile-server: fault: %s\n", fault.c_str());
      return 1;
    }
    return 0;
  } catch (const BadInput& e) {
    std::fprintf(stderr, "tactile-server: %s\n%s", e.message.c_str(), kUsage);
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

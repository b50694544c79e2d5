// The tools' command lines, read with CLI11 (Debian: libcli11-dev): each tool
// declares its options once, and its usage text is made from them.
#pragma once

#include <cmath>
#include <functional>
#include <iostream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "tactile_version.hpp"

namespace tactile {

// What every tool shares: -h/--help prints the usage with every subcommand's
// options; --version the project's version and the protocol's; an option
// given twice keeps its last value, as scripts/run.sh relies on (the user's
// options come after its own).
inline void configure_command_line(CLI::App& app) {
  app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  app.set_help_flag();
  app.set_help_all_flag("-h,--help", "print this help and exit");
  app.set_version_flag("--version", app.get_name() + " " + kVersion + " (protocol " + kProtocolVersion + ")",
                       "print the version and exit");
}

// Parses argv into the options bound to `app`: nullopt when the tool is to
// run, else its exit status: 0 after --help (the usage on stdout), 2 after bad
// usage ("<tool>: <what is wrong>" and the usage on stderr).
inline std::optional<int> parse_command_line(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::CallForVersion& e) {
    std::cout << e.what() << "\n";
    return 0;
  } catch (const CLI::CallForAllHelp&) {
    std::cout << app.help("", CLI::AppFormatMode::All);  // (a subcommand's, after `tool SUBCOMMAND --help`)
    return 0;
  } catch (const CLI::ParseError& e) {
    std::cerr << app.get_name() << ": " << e.what() << "\n\n" << app.help("", CLI::AppFormatMode::All);
    return 2;
  }
}

// A finite number for which `ok` holds; `rule` says which in the message
// ("--dt: must be > 0, got -1"). It adds nothing to the usage text: the
// option's description says the rule in words.
inline CLI::Validator number_where(std::function<bool(double)> ok, std::string rule) {
  return CLI::Validator(
      [ok = std::move(ok), rule = std::move(rule)](std::string& text) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v)) return "not a number: " + text;
        return ok(v) ? std::string() : "must be " + rule + ", got " + text;
      },
      "");
}

inline CLI::Validator finite_number() {
  return number_where([](double) { return true; }, "a number");
}

inline CLI::Validator positive_number() {
  return number_where([](double v) { return v > 0; }, "> 0");
}

// One of a few words ("--precision: must be float or double, got half").
inline CLI::Validator one_of(std::vector<std::string> allowed) {
  std::string rule;
  for (size_t i = 0; i < allowed.size(); ++i)
    rule += (i == 0 ? "" : i + 1 == allowed.size() ? " or " : ", ") + allowed[i];
  return CLI::Validator(
      [allowed, rule](std::string& text) -> std::string {
        for (const std::string& w : allowed)
          if (text == w) return {};
        return "must be " + rule + ", got " + text;
      },
      "");
}

}  // namespace tactile

// flank: 5-axis flank milling patches from a design surface. A thin main: every subcommand
// lives in its own cmd_*.cpp and reports its exit code.
#include <CLI/CLI.hpp>

#include <cstdlib>
#include <string_view>

#include "cli/commands.h"
#include "kernels/memory.h"

int main(int argc, char** argv) {
  flank::retain_freed_memory();
  // FLANK_HUGE_PAGES=0 leaves the heap in 4 KiB pages (kernels/memory.h).
  if (const char* h = std::getenv("FLANK_HUGE_PAGES"); !h || std::string_view(h) != "0") flank::prefer_huge_pages();
  CLI::App app{
      "flank — finds patches of a design surface that one sweep of one rotary cutter can flank-mill,\n"
      "designs the cutter and its 5-axis motion, and proves the error and the collisions."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "flank 0.1.0");
  app.failure_message([](const CLI::App* failed, const CLI::Error& e) {
    std::string name = failed && failed->get_parent() ? " " + failed->get_name() : "";
    return "flank" + name + ": " + e.what() + " (see flank" + name + " --help)\n";
  });
  int exit_code = 0;
  flank::cli::register_info(app, &exit_code);
  flank::cli::register_movability(app, &exit_code);
  flank::cli::register_decompose(app, &exit_code);
  flank::cli::register_fit(app, &exit_code);
  flank::cli::register_synth(app, &exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  return exit_code;
}

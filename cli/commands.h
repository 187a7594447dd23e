// Each subcommand registers itself on the CLI11 app and returns its exit code through
// the callback. Errors at the edges (io::Error, bad options) become one line on stderr.
#pragma once

namespace CLI {
class App;
}

namespace flank::cli {

void register_info(CLI::App& app, int* exit_code);
void register_synth(CLI::App& app, int* exit_code);
void register_movability(CLI::App& app, int* exit_code);
void register_fit(CLI::App& app, int* exit_code);
void register_decompose(CLI::App& app, int* exit_code);

}  // namespace flank::cli

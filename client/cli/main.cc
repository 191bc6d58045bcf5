// swarf: the command-line client.
#include <iostream>
#include <string>
#include <vector>

#include "client/cli/commands.h"
#include "core/memory_policy.h"
#include "core/thread_pool.h"
#include "spdlog/spdlog.h"

namespace {

constexpr char kUsage[] =
    "usage: swarf <command> [options]\n"
    "commands:\n"
    "  run     simulate a toolpath (G-code or XYZ) and write pictures/meshes\n"
    "  table   the paper's Tables 1 and 2: error and time of both schemes\n"
    "  marks   the cutting marks (creases) of a paper instance\n"
    "  health  whether a running swarfd is serving\n"
    "  sessions  the sessions of a running swarfd\n"
    "  load    many sessions streaming at once: throughput and latency\n"
    "  view    the live 3D viewer of a running swarfd's session\n"
    "  moves   the interpreted moves of a program, one a line\n"
    "Run 'swarf <command> --help' for a command's options.\n"
    "Environment: SWARF_THREADS=N runs N threads a pool (default: one per\n"
    "core this process may use); SWARF_TOKEN (see --token).\n";

}  // namespace

int main(int argc, char** argv) {
  swarf::ReturnLargeBuffersOnFree();
  swarf::KeepFreedArenaTops();
  if (auto threads = swarf::ThreadsFromEnvironment(); !threads.ok()) {
    std::cerr << "swarf: " << threads.status().message() << "\n";
    return 2;
  }
  if (argc < 2) {
    std::cerr << kUsage;
    return 2;
  }
  // The embedded server logs session events at info; the CLI reports for
  // itself, so only its warnings and errors show.
  spdlog::set_level(spdlog::level::warn);
  const std::string cmd = argv[1];
  const std::vector<std::string> args(argv + 2, argv + argc);
  if (cmd == "run") return swarf::cli::RunCommand(args);
  if (cmd == "table") return swarf::cli::TableCommand(args);
  if (cmd == "marks") return swarf::cli::MarksCommand(args);
  if (cmd == "health") return swarf::cli::HealthCommand(args);
  if (cmd == "sessions") return swarf::cli::SessionsCommand(args);
  if (cmd == "load") return swarf::cli::LoadCommand(args);
  if (cmd == "view") return swarf::cli::ViewCommand(args);
  if (cmd == "moves") return swarf::cli::MovesCommand(args);
  if (cmd == "--help" || cmd == "-h" || cmd == "help") {
    std::cout << kUsage;
    return 0;
  }
  std::cerr << "swarf: unknown command \"" << cmd << "\"\n" << kUsage;
  return 2;
}

// swarf view: the live viewer attached to a session of a running swarfd.
#include <iostream>
#include <set>

#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/cli/connection.h"
#include "client/viewer/viewer.h"

namespace swarf::cli {
namespace {

constexpr char kUsage[] =
    "usage: swarf view --server HOST:PORT --session ID [options]\n"
    "Serves a page on 127.0.0.1 showing the session's workpiece in 3D while\n"
    "it is cut (any client's moves) and after. Ctrl-C stops it.\n"
    "options:\n"
    "  --view-port N                the page's port (default: a free one)\n"
    "  --token T                    the server's bearer token (or $SWARF_TOKEN)\n"
    "  --tls-ca FILE                use TLS, trusting this PEM CA\n"
    "  --tls-cert FILE --tls-key FILE   a client certificate for TLS\n";

}  // namespace

int ViewCommand(const std::vector<std::string>& argv) {
  std::set<std::string> valued = {"server", "session"};
  valued.insert(std::begin(kConnectionFlags), std::end(kConnectionFlags));
  valued.insert(std::begin(kViewerFlags), std::end(kViewerFlags));
  auto args = Args::Parse(argv, valued, {"help"});
  if (!args.ok()) {
    std::cerr << "swarf view: " << args.status().message() << "\n" << kUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage;
    return 0;
  }
  const auto server = args->Get("server");
  const auto session = args->Get("session");
  if (!server || server->empty() || !session || session->empty() ||
      !args->positional().empty()) {
    std::cerr << "swarf view: give --server HOST:PORT and --session ID\n"
              << kUsage;
    return 2;
  }
  auto fail = [](const absl::Status& s, int code) {
    std::cerr << "swarf view: " << s.message() << "\n";
    return code;
  };
  auto copt = ConnectionOptionsFrom(*args);
  if (!copt.ok()) return fail(copt.status(), 2);
  auto vopt = ViewerOptionsFrom(*args);
  if (!vopt.ok()) return fail(vopt.status(), 2);
  auto conn = Connection::Open(*server, *copt);
  if (!conn.ok()) return fail(conn.status(), 1);
  auto viewer = Viewer::Start(conn->get(), *session, *vopt);
  if (!viewer.ok()) return fail(viewer.status(), 1);
  std::cout << "swarf view: session " << *session << " at " << (*viewer)->url()
            << " (Ctrl-C to stop)" << std::endl;
  (*viewer)->ServeUntilInterrupted();
  return 0;
}

}  // namespace swarf::cli

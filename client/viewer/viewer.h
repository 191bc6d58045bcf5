// The live viewer: a web page on 127.0.0.1 that shows a session's workpiece
// in 3D (three.js) while it is cut and after.
//
// The viewer is a gRPC client of the session like any other (GetSession,
// GetTiles with since_version, Probe, GetCuttingMarks, GetErrorStats): it
// relays them to the page over HTTP and adds no path into core/. A relay
// thread polls GetSession and fetches only the tiles changed since the last
// version it holds (coalesced: a tile that changed several times between two
// polls comes once, at its latest version), keeps them, subsampled to at most
// kMaxDisplayNodes per side, and the page fetches from that cache only what
// changed since its own version. Progress goes to the page as Server-Sent
// Events.
//
// HTTP: cpp-httplib (Debian libcpp-httplib-dev). Chosen over Boost.Beast and
// libwebsockets because the page needs plain GETs plus one server-to-page
// event stream, which SSE over a chunked response gives without WebSocket
// framing; cpp-httplib does that in a few lines with its thread pool, is a
// small compiled library (not Boost's build weight on a 2-core box) and
// needs no event loop of its own next to gRPC's.
//
// three.js comes from Debian's libjs-three, read from its installed path at
// start (nothing is fetched; no CDN). The page itself is embedded in the
// binary at build time.
#ifndef SWARF_CLIENT_VIEWER_VIEWER_H_
#define SWARF_CLIENT_VIEWER_VIEWER_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/cli/connection.h"
#include "client/outputs/deviation.h"
#include "design/design_mesh.h"

namespace swarf::cli {

// Node columns/rows the page gets at most per side: larger grids are sent
// every 2nd, 4th, ... node (a power of two, so that tiles subsample alike).
inline constexpr int32_t kMaxDisplayNodes = 1024;

struct ViewerOptions {
  std::string host = "127.0.0.1";
  int port = 0;  // 0: a free one
  // Directory holding three.min.js and examples/js/controls/OrbitControls.js;
  // empty: $SWARF_THREE_DIR, then libjs-three's installed path.
  std::string three_dir;
  double poll_seconds = 0.1;  // relay's GetSession period
};

// The toolpath as the client that streams it knows it (swarf run): tip
// positions and, per point, the session's moves applied once the tool is
// there. Without it (swarf view) the page's path is the tool positions the
// relay saw.
struct ViewerPath {
  std::vector<Vec3> points;
  std::vector<int64_t> moves_at;  // same size, non-decreasing
  std::vector<int32_t> tools;     // same size: the tool cutting to it
  int64_t moves_total = 0;
  // Each move's program line (by move id) and the files they index: the
  // pointer's readout names the line that cut there. Empty: move ids.
  std::vector<SourceLine> move_lines;
  std::vector<std::string> sources;
  // The design the session was given (SetDesign), for the page's
  // translucent overlay (not owned; outlives the viewer; null: none), and
  // the verdict's allowance and tolerance for the deviation colouring.
  const design::DesignMesh* design = nullptr;
  double allowance = 0, tolerance = 0.01;
};

// A safety finding drawn on the part (swarf run's checks, issue 30).
struct ViewerMarker {
  Vec3 at;
  std::string kind;  // stats.json's name: "rapid_cuts", ...
  std::string file;
  int32_t line = 0;
  double depth = 0, volume_mm3 = 0;
};

class ViewerImpl;

// Thread-safe. Serves until destroyed.
class Viewer {
 public:
  // Starts serving session `session_id` of `conn` (which must outlive the
  // viewer). NotFound naming the session if the server does not have it;
  // FailedPrecondition if three.js is not installed; Unavailable if the
  // port cannot be bound.
  static absl::StatusOr<std::unique_ptr<Viewer>> Start(
      Connection* conn, const std::string& session_id,
      const ViewerOptions& options, ViewerPath path = {});
  ~Viewer();

  int port() const;
  std::string url() const;
  // Blocks until a page has opened (its event stream is connected).
  void WaitForPage();
  // Safety findings to mark on the part, and air moves (feed moves that
  // removed nothing) to draw dashed, as the client learns them. Thread-safe.
  void AddSafety(std::vector<ViewerMarker> markers,
                 std::vector<std::pair<Vec3, Vec3>> air);
  // The streaming client is done (the page says so); the viewer keeps
  // serving.
  void MarkFinished();
  // Blocks until SIGINT or SIGTERM.
  void ServeUntilInterrupted();

 private:
  explicit Viewer(std::unique_ptr<ViewerImpl> impl);
  std::unique_ptr<ViewerImpl> impl_;
};

// The viewer's command-line flags (for Args::Parse) and its options from
// them: --view-port N (InvalidArgument naming it when bad).
inline const char* const kViewerFlags[] = {"view-port"};
class Args;
absl::StatusOr<ViewerOptions> ViewerOptionsFrom(const Args& args);

// The path of the runs `StreamPath` sends, with its move counts.
ViewerPath ViewerPathOf(const std::vector<PathRun>& runs);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_VIEWER_VIEWER_H_

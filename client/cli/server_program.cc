#include "client/cli/server_program.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"

namespace swarf::cli {

pb::ProgramOptions ProgramOptionsFor(const gcode::GcodeOptions& o, bool strict,
                                     int64_t batch_points,
                                     const std::string& name) {
  pb::ProgramOptions p;
  p.set_name(name);
  switch (o.dialect) {
    case gcode::Dialect::kLinuxCnc:
      p.set_dialect(pb::DIALECT_LINUXCNC);
      break;
    case gcode::Dialect::kFanuc:
      p.set_dialect(pb::DIALECT_FANUC);
      break;
    case gcode::Dialect::kGrbl:
      p.set_dialect(pb::DIALECT_GRBL);
      break;
  }
  p.mutable_arc_tolerance()->set_value(o.arc_tolerance);
  auto point = [](const double v[3], pb::Point3* out) {
    out->set_x(v[0]);
    out->set_y(v[1]);
    out->set_z(v[2]);
  };
  if (o.start_known) point(o.start, p.mutable_start());
  if (o.home_known) point(o.home, p.mutable_home());
  if (o.tool_change_position_known) {
    point(o.tool_change_position, p.mutable_tool_change_position());
  }
  p.set_m6_forgets_position(o.m6_forgets_position);
  p.set_max_blocks(o.max_blocks);
  p.set_strict(strict);
  p.set_batch_points(static_cast<int32_t>(batch_points));
  return p;
}

absl::Status StreamProgram(
    Connection& conn, const std::string& session_id, const std::string& text,
    pb::ProgramOptions options, StreamProgress* p,
    const std::function<void(const StreamProgress&)>& progress,
    const std::function<void(const pb::Ack&, int64_t first_move_id)>& on_ack,
    pb::ProgramDone* done) {
  options.set_report_cuts(on_ack != nullptr);
  // Chunks well under every message limit (gRPC's 4 MiB default included).
  constexpr size_t kChunk = 1 << 20;
  std::vector<pb::SimulateRequest> upload;
  for (size_t off = 0; off < text.size() || off == 0; off += kChunk) {
    pb::ProgramChunk* c = upload.emplace_back().mutable_program();
    c->set_request_id(1);
    c->set_offset(off);
    c->set_data(text.substr(off, kChunk));
    c->set_last(off + kChunk >= text.size());
    if (c->last()) *c->mutable_options() = options;
  }
  std::vector<pb::SimulateRequest> resume(1);
  resume[0].mutable_program()->set_request_id(1);
  resume[0].mutable_program()->set_resume(true);
  resume[0].mutable_program()->set_last(true);
  resume[0].mutable_program()->mutable_options()->set_first_seq(
      options.first_seq());
  const std::vector<pb::SimulateRequest>* send = &upload;
  uint64_t acked = options.first_seq() - 1;
  constexpr auto kResumeWindow = std::chrono::seconds(120);
  auto deadline = std::chrono::steady_clock::now() + kResumeWindow;
  for (int attempt = 0;; ++attempt) {
    auto ctx = conn.Context(session_id, 24 * 3600);
    auto stream = conn.stub().Simulate(ctx.get());
    std::thread writer([&] {
      for (const pb::SimulateRequest& r : *send) {
        if (!stream->Write(r)) break;  // Finish says why
      }
      stream->WritesDone();
    });
    pb::SimulateResponse resp;
    absl::Status error;
    bool finished = false, journal_missing = false;
    while (stream->Read(&resp)) {
      if (resp.has_ack()) {
        const pb::Ack& a = resp.ack();
        if (a.seq() <= acked) continue;
        acked = a.seq();
        p->moves_done = std::max(p->moves_done, a.moves_applied());
        if (on_ack && !a.duplicate()) {
          on_ack(a, a.moves_applied() - a.removed_mm3_size());
        }
        p->node_lowerings += a.node_lowerings();
        if (progress) progress(*p);
      } else if (resp.has_program_done()) {
        *done = resp.program_done();
        finished = true;
      } else if (resp.has_error() && error.ok()) {
        if (send == &resume &&
            resp.error().code() ==
                static_cast<int>(absl::StatusCode::kFailedPrecondition)) {
          journal_missing = true;  // not journaled: upload it again
        } else {
          error = absl::Status(
              static_cast<absl::StatusCode>(resp.error().code()),
              resp.error().message());
        }
        ctx->TryCancel();
      }
    }
    writer.join();
    grpc::Status st = stream->Finish();
    if (!error.ok()) return error;
    if (finished) return absl::OkStatus();
    if (journal_missing) {
      send = &upload;
      continue;
    }
    absl::StatusOr<std::optional<pb::Session>> back =
        AfterBrokenStream(conn, session_id, st, deadline, attempt);
    if (!back.ok()) return back.status();
    if (!back->has_value()) continue;
    const pb::Session& session = **back;
    acked = std::max<uint64_t>(acked, session.last_seq());
    p->moves_done = std::max(p->moves_done, session.moves_applied());
    std::fprintf(stderr,
                 "\nswarf: the stream to the server broke (%s); resuming the "
                 "program after batch %llu\n",
                 st.ok() ? "ended early" : st.error_message().c_str(),
                 static_cast<unsigned long long>(acked));
    send = &resume;
    deadline = std::chrono::steady_clock::now() + kResumeWindow;
  }
}

}  // namespace swarf::cli

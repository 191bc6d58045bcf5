// Small helpers shared by the tests that run the real server
// (server_integration_test, bad_input_test): unwrapping core results and
// building the requests both tests send. Stateless; header only.
#ifndef SWARF_TESTS_SERVER_TEST_UTIL_H_
#define SWARF_TESTS_SERVER_TEST_UTIL_H_

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "core/stock.h"
#include "swarf/v1/swarf.pb.h"

namespace swarf::testing {

// The value, or the status printed to stderr and abort(): for core calls
// that cannot fail in a correct test.
template <typename T>
T ValueOrDie(absl::StatusOr<T> v) {
  if (!v.ok()) {
    std::fprintf(stderr, "%s\n", v.status().ToString().c_str());
    std::abort();
  }
  return *std::move(v);
}

// Sets the request's stock rectangle and element counts from `stock`.
inline void SetStock(const StockSpec& stock,
                     ::swarf::v1::CreateSessionRequest* r) {
  ::swarf::v1::Stock* st = r->mutable_stock();
  st->set_x0(stock.x0);
  st->set_y0(stock.y0);
  st->set_x1(stock.x1);
  st->set_y1(stock.y1);
  st->set_z_top(stock.z_top);
  r->set_nx(stock.nx);
  r->set_ny(stock.ny);
}

// A Simulate request of one MoveBatch: `xyz` as given (unchecked, so it may
// be bad on purpose), cut with tool `tool`.
inline ::swarf::v1::SimulateRequest MovesRequest(
    uint64_t seq, int32_t tool, const std::vector<double>& xyz) {
  ::swarf::v1::SimulateRequest r;
  r.mutable_moves()->set_seq(seq);
  r.mutable_moves()->set_tool_id(tool);
  r.mutable_moves()->mutable_xyz()->Assign(xyz.begin(), xyz.end());
  return r;
}

}  // namespace swarf::testing

#endif  // SWARF_TESTS_SERVER_TEST_UTIL_H_

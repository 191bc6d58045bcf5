// A pool of worker threads running queued tasks in FIFO order. The server
// runs all simulation work here, never in a gRPC callback.
#ifndef SWARF_SERVER_EXECUTOR_H_
#define SWARF_SERVER_EXECUTOR_H_

#include <deque>
#include <functional>
#include <thread>
#include <vector>

#include "absl/synchronization/mutex.h"

namespace swarf::server {

// Thread-safe. The destructor finishes the queued tasks, then joins.
class Executor {
 public:
  explicit Executor(int threads);
  ~Executor();
  Executor(const Executor&) = delete;
  Executor& operator=(const Executor&) = delete;

  void Schedule(std::function<void()> task);

 private:
  void Loop();

  absl::Mutex mu_;
  std::deque<std::function<void()>> tasks_ ABSL_GUARDED_BY(mu_);
  bool stop_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<std::thread> threads_;
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_EXECUTOR_H_

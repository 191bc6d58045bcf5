// A pool of worker threads running queued tasks in FIFO order. The server
// runs all simulation work here, never in a gRPC callback; work that may
// wait on a client for long runs on a thread of its own (StartThread).
#ifndef SWARF_SERVER_EXECUTOR_H_
#define SWARF_SERVER_EXECUTOR_H_

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <thread>
#include <vector>

#include "absl/synchronization/mutex.h"

namespace swarf::server {

// Thread-safe. The destructor finishes the queued tasks, then joins the
// pool's threads and those of StartThread.
class Executor {
 public:
  explicit Executor(int threads);
  ~Executor();
  Executor(const Executor&) = delete;
  Executor& operator=(const Executor&) = delete;

  void Schedule(std::function<void()> task);

  // Runs `task` at once on a new thread, not one of the pool's: for work
  // that waits on a client for as long as the client takes (a
  // GetCuttingMarks search waits while its queue is full). The pool has one
  // thread per core for every session's calls; a few slow readers there
  // would stall them all. The task must end by itself (a cancelled call
  // stops its search): the destructor waits for it. False, and `task` not
  // run, when the system makes no more threads.
  bool StartThread(std::function<void()> task);

 private:
  void Loop();
  // Joins the threads of StartThread whose task has ended.
  void JoinEndedLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(own_mu_);

  absl::Mutex mu_;
  std::deque<std::function<void()>> tasks_ ABSL_GUARDED_BY(mu_);
  bool stop_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<std::thread> threads_;

  absl::Mutex own_mu_;  // StartThread's
  uint64_t next_own_ ABSL_GUARDED_BY(own_mu_) = 0;
  std::map<uint64_t, std::thread> own_ ABSL_GUARDED_BY(own_mu_);
  std::vector<uint64_t> ended_ ABSL_GUARDED_BY(own_mu_);
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_EXECUTOR_H_

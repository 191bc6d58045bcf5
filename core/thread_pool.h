// A fixed pool of worker threads running data-parallel loops.
#ifndef SWARF_CORE_THREAD_POOL_H_
#define SWARF_CORE_THREAD_POOL_H_

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"

namespace swarf {

// The cores this process may run on: its CPU affinity mask's count where
// the system has one (taskset, a container's cpuset), else
// std::thread::hardware_concurrency(); at least 1.
int AvailableCores();

// The value of SWARF_THREADS, the environment variable that sets the
// default thread count: a whole number in [1, 1024]. nullopt when unset;
// InvalidArgument naming the variable and the value when it is anything
// else (the programs' mains refuse to start then).
absl::StatusOr<std::optional<int>> ThreadsFromEnvironment();

// The threads a pool (and swarfd's executor) gets by default: SWARF_THREADS
// where it is valid (to leave cores to other work, or to run as a many-core
// machine would, its memory measured on a small one), else
// AvailableCores().
int DefaultThreads();

// ParallelFor may be called from several threads at once; each call blocks
// until its loop is done, and the calling thread works on it too. The
// workers share themselves between the loops in flight: an idle worker
// takes the loop with the fewest threads (its caller counted), the newest
// of those, and when a loop starts every worker finishes its run of
// indices and chooses again, so a loop started beside a long one gets its
// share of the threads at once. A caller whose own indices are all claimed
// works on the loops its loop's items started until its loop is done.
class ThreadPool {
 public:
  // threads <= 0: DefaultThreads() (one per core this process may run on,
  // unless SWARF_THREADS says otherwise).
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  // Runs fn(i) for every i in [0, n), in any order and on any thread
  // (indices are claimed in runs of about n / (1024 * size())).
  //
  // A diagnostic: with SWARF_LOOP_PROFILE=N in the environment, each item
  // is timed (its thread's CPU time) and, when the process exits, a line
  // per loop body (its function and lambda number) goes to stderr: calls,
  // items, CPU and wall seconds, and the loop's time modelled on N threads
  // (its runs of items, in order, each to the thread free first) against
  // CPU / N. It shows the loops that too few or too uneven items keep from
  // N cores, measured on any machine: run with SWARF_THREADS=N as well, so
  // that loops sized by the pool take their size on N. Loops run from
  // another loop's items are marked [in]; an item's CPU time leaves out
  // what other threads do for the loops it starts.
  void ParallelFor(int64_t n, const std::function<void(int64_t)>& fn);

  // A process-wide pool with one thread per available core.
  static ThreadPool& Default();

 private:
  struct Job;
  void WorkerLoop();
  // ParallelFor without the profile.
  void Loop(int64_t n, const std::function<void(int64_t)>& fn);
  // Works on `job` (holding *l, which it releases meanwhile) until its
  // indices are all claimed or another loop starts.
  void Work(Job* job, std::unique_lock<std::mutex>* l);

  std::mutex mu_;
  std::condition_variable cv_;       // work arrived, or stop
  std::condition_variable job_cv_;   // a thread left a job, or one started
  std::vector<Job*> jobs_;  // guarded by mu_
  bool stop_ = false;       // guarded by mu_
  // Counts the loops started; a worker that sees it change leaves its
  // loop to choose again. Written under mu_, read without it.
  std::atomic<uint64_t> started_{0};
  std::vector<std::thread> workers_;
};

// v[0..n) = value on every thread of pool (n >= 0), 64 Ki elements a task:
// for large buffers left unfilled (UnfilledVector), whose first writes on
// one thread also page-faulted them in on one.
template <typename T>
void FillOnEvery(ThreadPool& pool, T* v, int64_t n, T value) {
  constexpr int64_t kChunk = int64_t{1} << 16;
  pool.ParallelFor((n + kChunk - 1) / kChunk, [&](int64_t c) {
    std::fill(v + c * kChunk, v + std::min(n, (c + 1) * kChunk), value);
  });
}

}  // namespace swarf

#endif  // SWARF_CORE_THREAD_POOL_H_

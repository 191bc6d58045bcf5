#include "core/thread_pool.h"

#include <cxxabi.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <queue>
#include <string>
#include <string_view>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

#ifdef __linux__
#include <sched.h>
#endif

namespace swarf {

int AvailableCores() {
#ifdef __linux__
  // hardware_concurrency() counts the machine's cores, not those a taskset
  // or a container's cpuset leaves: more threads than cores only contend.
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof set, &set) == 0) {
    const int n = CPU_COUNT(&set);
    if (n > 0) return n;
  }
#endif
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

absl::StatusOr<std::optional<int>> ThreadsFromEnvironment() {
  const char* v = std::getenv("SWARF_THREADS");
  if (v == nullptr) return std::nullopt;
  int n = 0;
  if (!absl::SimpleAtoi(v, &n) || n < 1 || n > 1024) {
    return absl::InvalidArgumentError(absl::StrCat(
        "SWARF_THREADS must be a whole number from 1 to 1024, got \"", v,
        "\""));
  }
  return n;
}

int DefaultThreads() {
  const absl::StatusOr<std::optional<int>> n = ThreadsFromEnvironment();
  if (n.ok() && n->has_value()) return **n;
  return AvailableCores();
}

struct ThreadPool::Job {
  const std::function<void(int64_t)>* fn;
  // The loop whose item started this one (nullptr: none): it cannot end
  // before this one, so the chain of parents is alive while this is.
  const Job* parent = nullptr;
  int64_t n;
  int64_t grain;  // indices claimed at a time
  std::atomic<int64_t> next{0};
  // Threads inside Run(), its caller's included; guarded by the pool's mu_.
  int active = 0;

  bool Exhausted() const { return next.load() >= n; }

  bool Within(const Job* ancestor) const {
    for (const Job* j = parent; j != nullptr; j = j->parent) {
      if (j == ancestor) return true;
    }
    return false;
  }

  // Claims indices, `grain` at a time, and runs them until none are left,
  // or (with `started`) until it no longer reads `seen`.
  void Run(const std::atomic<uint64_t>* started = nullptr, uint64_t seen = 0) {
    for (int64_t i; (i = next.fetch_add(grain)) < n;) {
      const int64_t end = std::min(n, i + grain);
      for (; i < end; ++i) (*fn)(i);
      if (started != nullptr &&
          started->load(std::memory_order_relaxed) != seen) {
        return;
      }
    }
  }
};

namespace {
// The loop whose item this thread is running, if any.
thread_local const void* current_job = nullptr;

// Sets current_job for a scope.
class CurrentJob {
 public:
  explicit CurrentJob(const void* job) : saved_(current_job) {
    current_job = job;
  }
  ~CurrentJob() { current_job = saved_; }

 private:
  const void* saved_;
};

// The indices a thread claims at a time in a loop of n on `threads`
// (ParallelFor's runs, and the profile's model of them).
int64_t RunLength(int64_t n, int threads) {
  return std::max<int64_t>(1, n / (1024 * int64_t{threads}));
}

// SWARF_LOOP_PROFILE (thread_pool.h): each loop's figures, by the type
// of its body, printed when the process exits.
class LoopProfile {
 public:
  // Null unless SWARF_LOOP_PROFILE is a thread count in [1, 1024] (any
  // other value is named on stderr, once).
  static LoopProfile* Get() {
    static LoopProfile* const profile = [] {
      const char* v = std::getenv("SWARF_LOOP_PROFILE");
      if (v == nullptr) return static_cast<LoopProfile*>(nullptr);
      int threads = 0;
      if (!absl::SimpleAtoi(v, &threads) || threads < 1 || threads > 1024) {
        std::fprintf(stderr,
                     "SWARF_LOOP_PROFILE must be a thread count in [1, 1024], "
                     "got \"%s\": no loop profile\n",
                     v);
        return static_cast<LoopProfile*>(nullptr);
      }
      static LoopProfile p(threads);  // prints as the process exits
      return &p;
    }();
    return profile;
  }

  // One loop's items' CPU seconds, in index order, and its wall seconds.
  void Add(const std::function<void(int64_t)>& fn, bool inner,
           const std::vector<float>& cpu, double wall) {
    double sum = 0;
    for (float c : cpu) sum += c;
    const double modelled = Modelled(cpu);
    std::string name = BodyName(fn);
    if (inner) name = "[in] " + name;
    std::lock_guard<std::mutex> l(mu_);
    Figures& f = loops_[name];
    ++f.calls;
    f.items += static_cast<int64_t>(cpu.size());
    f.cpu += sum;
    f.wall += wall;
    f.modelled += modelled;
  }

  ~LoopProfile() {
    std::lock_guard<std::mutex> l(mu_);
    std::vector<std::pair<std::string, Figures>> rows(loops_.begin(),
                                                      loops_.end());
    std::sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) {
      return a.second.cpu > b.second.cpu;
    });
    std::fprintf(stderr, "loop profile: %7s %9s %8s %8s %8s %8s  %s\n", "calls",
                 "items", "cpu s", "wall s",
                 absl::StrCat("on ", threads_).c_str(), "cpu/n", "loop");
    for (const auto& [name, f] : rows) {
      std::fprintf(
          stderr, "loop profile: %7lld %9lld %8.3f %8.3f %8.3f %8.3f  %s\n",
          static_cast<long long>(f.calls), static_cast<long long>(f.items),
          f.cpu, f.wall, f.modelled, f.cpu / threads_, name.c_str());
    }
  }

 private:
  struct Figures {
    int64_t calls = 0, items = 0;
    double cpu = 0, wall = 0, modelled = 0;
  };

  explicit LoopProfile(int threads) : threads_(threads) {}

  // The loop on threads_ threads: its runs of items (as ParallelFor
  // claims them), in order, each to the thread free first; the last to
  // finish.
  double Modelled(const std::vector<float>& cpu) const {
    const int64_t n = static_cast<int64_t>(cpu.size());
    const int64_t grain = RunLength(n, threads_);
    std::priority_queue<double, std::vector<double>, std::greater<double>>
        free_at;
    for (int t = 0; t < threads_; ++t) free_at.push(0);
    double end = 0;
    for (int64_t i = 0; i < n; i += grain) {
      double run = 0;
      for (int64_t k = i; k < std::min(n, i + grain); ++k) run += cpu[k];
      const double done = free_at.top() + run;
      free_at.pop();
      free_at.push(done);
      end = std::max(end, done);
    }
    return end;
  }

  // "swarf::Workpiece::Apply::{lambda(long)#3}": the function a lambda is
  // in, and its number there (GCC's spelling; clang's is "$_N", numbered in
  // the file).
  static std::string BodyName(const std::function<void(int64_t)>& fn) {
    int status = 0;
    std::unique_ptr<char, void (*)(void*)> demangled(
        abi::__cxa_demangle(fn.target_type().name(), nullptr, nullptr, &status),
        std::free);
    std::string full =
        demangled != nullptr ? demangled.get() : fn.target_type().name();
    // Parentheses only around the function's parameters.
    constexpr std::string_view kAnonymous = "(anonymous namespace)::";
    for (size_t at; (at = full.find(kAnonymous)) != std::string::npos;) {
      full.erase(at, kAnonymous.size());
    }
    std::string name = full.substr(0, full.find('('));
    const size_t lambda = full.rfind("{lambda");
    const size_t clang_lambda = full.rfind("::$");
    if (lambda != std::string::npos) {
      name += "::" + full.substr(lambda, full.find('}', lambda) - lambda + 1);
    } else if (clang_lambda != std::string::npos) {
      name += full.substr(clang_lambda, full.find(':', clang_lambda + 2) -
                                            clang_lambda);
    }
    return name;
  }

  const int threads_;
  std::mutex mu_;
  std::map<std::string, Figures> loops_;  // guarded by mu_
};

double ThreadCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace

ThreadPool::ThreadPool(int threads) {
  if (threads <= 0) {
    threads = DefaultThreads();
  }
  for (int i = 1; i < threads; ++i) {
    workers_.emplace_back([this] { WorkerLoop(); });
  }
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : workers_) t.join();
}

void ThreadPool::WorkerLoop() {
  std::unique_lock<std::mutex> l(mu_);
  for (;;) {
    cv_.wait(l, [this] { return stop_ || !jobs_.empty(); });
    if (stop_) return;
    // A job leaves the list once all its indices are claimed.
    std::erase_if(jobs_, [](const Job* j) { return j->Exhausted(); });
    if (jobs_.empty()) continue;
    // The loop with the fewest threads, the newest of those. Taking the
    // oldest alone left a loop started beside a long one (the marks
    // beside the error statistics) on its calling thread; on a tie the
    // newer loop's caller is alone more often (one worker, two loops).
    Job* job = jobs_.front();
    for (Job* j : jobs_) {
      if (j->active <= job->active) job = j;
    }
    Work(job, &l);
  }
}

void ThreadPool::Work(Job* job, std::unique_lock<std::mutex>* l) {
  ++job->active;
  const uint64_t seen = started_.load(std::memory_order_relaxed);
  l->unlock();
  {
    CurrentJob in(job);
    job->Run(&started_, seen);
  }
  l->lock();
  if (--job->active == 0) job_cv_.notify_all();
}

void ThreadPool::ParallelFor(int64_t n,
                             const std::function<void(int64_t)>& fn) {
  if (n <= 0) return;
  if (LoopProfile* profile = LoopProfile::Get()) {
    // Each item's CPU time on its own thread: not its wall time, which
    // another thread's work on the same core stretches.
    std::vector<float> cpu(n);
    const bool inner = current_job != nullptr;
    const auto t0 = std::chrono::steady_clock::now();
    Loop(n, [&](int64_t i) {
      const double c0 = ThreadCpuSeconds();
      fn(i);
      cpu[i] = static_cast<float>(ThreadCpuSeconds() - c0);
    });
    profile->Add(
        fn, inner, cpu,
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
            .count());
    return;
  }
  Loop(n, fn);
}

void ThreadPool::Loop(int64_t n, const std::function<void(int64_t)>& fn) {
  if (n == 1 || workers_.empty()) {
    for (int64_t i = 0; i < n; ++i) fn(i);
    return;
  }
  Job job;
  job.fn = &fn;
  job.n = n;
  job.parent = static_cast<const Job*>(current_job);
  // Loops of many small items (a mesh's leaves) spent more on claiming
  // indices one by one than on the items, and threads writing
  // neighbouring items shared cache lines. Runs of indices fix both. Work
  // is often bunched in a few items (the valuation's bins under a
  // toolpath): 1024 runs per thread keep it balanced (64 made the
  // valuation of BM_Read 10% slower), and loops of under 2048 items per
  // thread still go one index at a time.
  job.grain = RunLength(n, size());
  {
    std::lock_guard<std::mutex> l(mu_);
    job.active = 1;  // the caller
    jobs_.push_back(&job);
    // Workers in other loops leave them after their current run of
    // indices and choose again, this one among them.
    started_.fetch_add(1, std::memory_order_relaxed);
  }
  cv_.notify_all();
  job_cv_.notify_all();  // callers waiting for a loop this one is within
  CurrentJob in(&job);
  job.Run();
  // Every index is claimed; once no worker is inside the job, every index
  // has also finished and the job can leave the list.
  std::unique_lock<std::mutex> l(mu_);
  jobs_.erase(std::remove(jobs_.begin(), jobs_.end(), &job), jobs_.end());
  --job.active;
  // Meanwhile the caller works on the loops started by this one's items
  // (and theirs): it waits for them anyway. Idle, it left a loop started
  // beside a long item with one thread fewer (the marks' projection beside
  // their chaining). Other loops it leaves to the workers: one of their
  // items could keep it long after its own loop ended.
  for (;;) {
    if (job.active == 0) return;
    Job* inner = nullptr;
    for (Job* j : jobs_) {
      if (!j->Exhausted() && j->Within(&job)) {
        inner = j;
        break;
      }
    }
    if (inner == nullptr) {
      job_cv_.wait(l);
      continue;
    }
    Work(inner, &l);
  }
}

ThreadPool& ThreadPool::Default() {
  static ThreadPool* const pool = new ThreadPool(0);
  return *pool;
}

}  // namespace swarf

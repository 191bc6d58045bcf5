// ThreadPool::ParallelFor runs every index exactly once, also when several
// threads call it at the same time.
#include "core/thread_pool.h"

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/bucket_starts.h"
#include "gtest/gtest.h"

#ifdef __linux__
#include <sched.h>
#endif

namespace swarf {
namespace {

// Runs a loop of n on the pool and checks each index ran exactly once.
void ExpectEachIndexOnce(ThreadPool& pool, int64_t n) {
  std::unique_ptr<std::atomic<int>[]> hits(new std::atomic<int>[n + 1]);
  for (int64_t i = 0; i <= n; ++i) hits[i] = 0;
  pool.ParallelFor(n, [&](int64_t i) {
    ASSERT_GE(i, 0);
    ASSERT_LT(i, n);
    hits[i].fetch_add(1, std::memory_order_relaxed);
  });
  // ParallelFor has returned: every call has finished.
  int64_t wrong = 0;
  for (int64_t i = 0; i < n; ++i) wrong += hits[i].load() != 1;
  EXPECT_EQ(wrong, 0) << "n = " << n;
  EXPECT_EQ(hits[n].load(), 0);
}

// A loop item that counts itself in `inside`, keeps in `most` the most
// items inside at once, and waits (until `deadline`) for that to reach two.
void WaitForCompany(std::atomic<int>& inside, std::atomic<int>& most,
                    std::chrono::steady_clock::time_point deadline) {
  const int now = ++inside;
  for (int m = most.load(); now > m && !most.compare_exchange_weak(m, now);) {
  }
  while (most.load() < 2 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  --inside;
}

#ifdef __linux__
// Held to one core (as `taskset -c N` does), a default pool has one
// thread: the machine's other cores are not ours to contend for.
TEST(ThreadPoolTest, DefaultSizeFollowsTheAffinityMask) {
  cpu_set_t all;
  ASSERT_EQ(sched_getaffinity(0, sizeof all, &all), 0);
  EXPECT_EQ(AvailableCores(), CPU_COUNT(&all));
  EXPECT_EQ(ThreadPool().size(), CPU_COUNT(&all));
  int first = 0;
  while (!CPU_ISSET(first, &all)) ++first;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(first, &one);
  ASSERT_EQ(sched_setaffinity(0, sizeof one, &one), 0);
  const int held = AvailableCores();
  const int pool = ThreadPool().size();
  ASSERT_EQ(sched_setaffinity(0, sizeof all, &all), 0);
  EXPECT_EQ(held, 1);
  EXPECT_EQ(pool, 1);
}
#endif

// SWARF_THREADS sets the default size, whatever the cores; anything but a
// whole number in [1, 1024] is an error naming it, and the cores decide.
TEST(ThreadPoolTest, SwarfThreadsSetsTheDefaultSize) {
  const char* before = std::getenv("SWARF_THREADS");
  const std::string saved = before != nullptr ? before : "";
  ASSERT_EQ(setenv("SWARF_THREADS", "13", 1), 0);
  EXPECT_EQ(DefaultThreads(), 13);
  EXPECT_EQ(ThreadPool().size(), 13);
  ASSERT_TRUE(ThreadsFromEnvironment().ok());
  EXPECT_EQ(*ThreadsFromEnvironment(), 13);
  for (const char* bad : {"0", "-2", "1025", "4x", "", "many"}) {
    ASSERT_EQ(setenv("SWARF_THREADS", bad, 1), 0);
    const auto t = ThreadsFromEnvironment();
    EXPECT_EQ(t.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(t.status().message().find(absl::StrCat("SWARF_THREADS must be "
                                                     "a whole number from 1 "
                                                     "to 1024, got \"",
                                                     bad, "\"")),
              std::string::npos)
        << t.status();
    EXPECT_EQ(DefaultThreads(), AvailableCores()) << bad;
  }
  ASSERT_EQ(unsetenv("SWARF_THREADS"), 0);
  EXPECT_FALSE(ThreadsFromEnvironment()->has_value());
  EXPECT_EQ(DefaultThreads(), AvailableCores());
  if (before != nullptr) setenv("SWARF_THREADS", saved.c_str(), 1);
}

TEST(ThreadPoolTest, EveryIndexExactlyOnce) {
  for (int threads : {1, 2, 4, 7}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.size(), threads);
    for (int64_t n : {0, 1, 2, 3, 17, 1000, 100003}) {
      ExpectEachIndexOnce(pool, n);
    }
  }
}

TEST(ThreadPoolTest, NegativeCountRunsNothing) {
  ThreadPool pool(3);
  std::atomic<int> calls{0};
  pool.ParallelFor(-5, [&](int64_t) { ++calls; });
  EXPECT_EQ(calls.load(), 0);
}

TEST(ThreadPoolTest, DefaultPoolWorks) {
  EXPECT_GE(ThreadPool::Default().size(), 1);
  EXPECT_EQ(&ThreadPool::Default(), &ThreadPool::Default());
  ExpectEachIndexOnce(ThreadPool::Default(), 5000);
}

// Plain (non-atomic) writes made inside the loop are visible after it.
TEST(ThreadPoolTest, ResultsVisibleAfterReturn) {
  ThreadPool pool(4);
  std::vector<int64_t> out(50000, -1);
  pool.ParallelFor(static_cast<int64_t>(out.size()),
                   [&](int64_t i) { out[i] = i * i; });
  for (int64_t i = 0; i < static_cast<int64_t>(out.size()); ++i) {
    ASSERT_EQ(out[i], i * i);
  }
}

TEST(ThreadPoolTest, ConcurrentCallersEachGetTheirLoop) {
  for (int threads : {1, 3}) {
    ThreadPool pool(threads);
    constexpr int kCallers = 6;
    constexpr int kRounds = 40;
    std::atomic<int64_t> failures{0};
    std::vector<std::thread> callers;
    for (int c = 0; c < kCallers; ++c) {
      callers.emplace_back([&, c] {
        for (int round = 0; round < kRounds; ++round) {
          // Different sizes so that loops of all lengths overlap.
          const int64_t n = 1 + (c * 977 + round * 131) % 3000;
          std::vector<std::atomic<int>> hits(n);
          for (auto& h : hits) h = 0;
          pool.ParallelFor(n, [&](int64_t i) {
            hits[i].fetch_add(1, std::memory_order_relaxed);
          });
          for (auto& h : hits) failures += h.load() != 1;
        }
      });
    }
    for (auto& t : callers) t.join();
    EXPECT_EQ(failures.load(), 0) << threads << " threads";
  }
}

// Indices are claimed in runs (about n / (1024 * size())), yet a loop of a
// few items is still shared: the first item waits for another thread to
// start one, which fails if one thread had claimed the whole loop.
TEST(ThreadPoolTest, FewItemsStillShared) {
  ThreadPool pool(2);
  for (int64_t n : {2, 128, 1000, 100000}) {
    std::atomic<int> started{0};
    std::atomic<bool> shared{false};
    pool.ParallelFor(n, [&](int64_t i) {
      ++started;
      if (i != 0) return;
      for (int k = 0; k < 10000 && started.load() < 2; ++k) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      shared = started.load() >= 2;
    });
    EXPECT_TRUE(shared.load()) << "n = " << n;
  }
}

// A loop started while a long one holds every worker gets its share of
// them at once, not when the long one ends: each item of the later loop
// waits until two threads are inside it together. Taking the oldest loop
// first left the later loop on its calling thread alone (the marks beside
// the error statistics), and this waited out its 10 s.
TEST(ThreadPoolTest, ALaterLoopGetsWorkersFromALongOne) {
  // Two threads: the only worker leaves the long loop to the later one's.
  for (int threads : {2, 4}) {
    SCOPED_TRACE(threads);
    ThreadPool pool(threads);
    std::atomic<bool> later_done{false};
    std::atomic<bool> long_started{false};
    std::thread long_caller([&] {
      pool.ParallelFor(1 << 20, [&](int64_t) {
        long_started = true;
        if (!later_done.load()) {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      });
    });
    while (!long_started.load()) std::this_thread::yield();
    // Let every worker settle into the long loop.
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::atomic<int> inside{0};
    std::atomic<int> most{0};
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::seconds(10);
    pool.ParallelFor(8,
                     [&](int64_t) { WaitForCompany(inside, most, deadline); });
    later_done = true;
    long_caller.join();
    EXPECT_GE(most.load(), 2);
  }
}

// A caller whose own indices are done helps with the loops its loop's
// items started: here the caller's item ends at once, and the only worker
// runs the other item, a loop whose items wait until two threads are
// inside it together. An idle caller left that loop to the worker alone,
// and this waited out its 10 s.
TEST(ThreadPoolTest, AWaitingCallerHelpsTheLoopsItsItemsStarted) {
  ThreadPool pool(2);
  const std::thread::id caller = std::this_thread::get_id();
  std::atomic<bool> inner_started{false};
  std::atomic<int> inside{0};
  std::atomic<int> most{0};
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::seconds(10);
  pool.ParallelFor(2, [&](int64_t) {
    if (std::this_thread::get_id() == caller) {
      while (!inner_started.load() &&
             std::chrono::steady_clock::now() < deadline) {
        std::this_thread::yield();
      }
      return;
    }
    pool.ParallelFor(8, [&](int64_t) {
      inner_started = true;
      WaitForCompany(inside, most, deadline);
    });
  });
  EXPECT_TRUE(inner_started.load());
  EXPECT_GE(most.load(), 2);
}

// A loop body may itself call ParallelFor on the same pool (the caller
// works on its own loop, so this cannot deadlock).
TEST(ThreadPoolTest, NestedLoops) {
  ThreadPool pool(3);
  std::vector<std::atomic<int>> hits(40 * 50);
  for (auto& h : hits) h = 0;
  pool.ParallelFor(40, [&](int64_t i) {
    pool.ParallelFor(50, [&](int64_t j) { hits[i * 50 + j].fetch_add(1); });
  });
  int wrong = 0;
  for (auto& h : hits) wrong += h.load() != 1;
  EXPECT_EQ(wrong, 0);
}

// Spins on this thread's CPU clock for about `seconds`.
void BurnCpu(double seconds) {
  timespec t0, t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t0);
  do {
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  } while ((t.tv_sec - t0.tv_sec) + 1e-9 * (t.tv_nsec - t0.tv_nsec) < seconds);
}

// SWARF_LOOP_PROFILE: a loop of 64 items, one of them 40 times as long as
// each other, on 4 threads: its line names the loop, counts the call and
// the items, and models it by its longest item (0.2 s at least), not by
// its CPU over 4 (about 0.13 s); a loop run from its items is marked [in].
// The lambda's name is GCC's or clang's (the sanitizer build's).
// In a child process (the profile prints as the process exits).
TEST(ThreadPoolDeathTest, LoopProfileModelsTheLongestItem) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        setenv("SWARF_LOOP_PROFILE", "4", 1);
        ThreadPool pool(4);
        pool.ParallelFor(64, [](int64_t i) { BurnCpu(i == 0 ? 0.2 : 0.005); });
        pool.ParallelFor(2, [&pool](int64_t) {
          pool.ParallelFor(3, [](int64_t) { BurnCpu(0.001); });
        });
        std::exit(0);
      },
      ::testing::ExitedWithCode(0),
      "loop profile: +1 +64 +0\\.[2-9][0-9]* +[0-9.]+ +0\\.[2-9][0-9]* "
      "+0\\.1[0-9]*  swarf::ThreadPoolDeathTest_LoopProfileModelsTheLongestItem"
      "_Test::TestBody::(\\{lambda\\(long\\)#1\\}|\\$_[0-9]+)\n.*  \\[in\\] "
      "swarf::");
}

// A value that is not a thread count is named, and nothing is profiled.
TEST(ThreadPoolDeathTest, LoopProfileNamesABadValue) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        setenv("SWARF_LOOP_PROFILE", "sixteen", 1);
        ThreadPool pool(2);
        pool.ParallelFor(4, [](int64_t) {});
        std::exit(0);
      },
      ::testing::ExitedWithCode(0),
      "^SWARF_LOOP_PROFILE must be a thread count in \\[1, 1024\\], got "
      "\"sixteen\": no loop profile\n$");
}

// BucketStarts places a parallel counting sort's chunks: counted on the
// pool and moved where it says, the items are std::stable_sort's by
// bucket, and bounds are where each bucket starts (empty ones too).
TEST(BucketStartsTest, ChunksCountedOnThePoolGiveTheStableSort) {
  ThreadPool pool(3);
  constexpr int64_t kItems = 10007, kChunks = 7, kBuckets = 13;
  std::vector<int64_t> key(kItems);
  for (int64_t i = 0; i < kItems; ++i) {
    key[i] = (i * 7919 % 101) % kBuckets == 5 ? 4 : (i * 7919 % 101) % kBuckets;
  }
  auto chunk_begin = [](int64_t c) { return c * kItems / kChunks; };
  std::vector<int64_t> at(kChunks * kBuckets, 0), bounds(kBuckets + 1);
  pool.ParallelFor(kChunks, [&](int64_t c) {
    for (int64_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) {
      ++at[c * kBuckets + key[i]];
    }
  });
  BucketStarts<int64_t>(kChunks, kBuckets, at.data(), bounds.data());
  std::vector<int64_t> placed(kItems, -1);
  pool.ParallelFor(kChunks, [&](int64_t c) {
    for (int64_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) {
      placed[at[c * kBuckets + key[i]]++] = i;
    }
  });
  std::vector<int64_t> sorted(kItems);
  for (int64_t i = 0; i < kItems; ++i) sorted[i] = i;
  std::stable_sort(sorted.begin(), sorted.end(),
                   [&](int64_t a, int64_t b) { return key[a] < key[b]; });
  EXPECT_EQ(placed, sorted);
  for (int64_t b = 0; b <= kBuckets; ++b) {
    EXPECT_EQ(bounds[b], std::count_if(key.begin(), key.end(),
                                       [b](int64_t k) { return k < b; }))
        << b;
  }
  EXPECT_EQ(bounds[5], bounds[6]);  // bucket 5 is empty
}

}  // namespace
}  // namespace swarf

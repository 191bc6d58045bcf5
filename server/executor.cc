#include "server/executor.h"

#include <system_error>

namespace swarf::server {

Executor::Executor(int threads) {
  if (threads < 1) threads = 1;
  for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { Loop(); });
}

Executor::~Executor() {
  {
    absl::MutexLock l(&mu_);
    stop_ = true;
  }
  for (auto& t : threads_) t.join();
  // Not joined under own_mu_: a task that ends takes it to say so.
  std::map<uint64_t, std::thread> own;
  {
    absl::MutexLock l(&own_mu_);
    own.swap(own_);
    ended_.clear();
  }
  for (auto& [id, t] : own) t.join();
}

bool Executor::StartThread(std::function<void()> task) {
  absl::MutexLock l(&own_mu_);
  JoinEndedLocked();
  const uint64_t id = next_own_++;
  // The thread says it ended under own_mu_, so after it is in own_.
  auto run = [this, id, task = std::move(task)] {
    task();
    absl::MutexLock l(&own_mu_);
    ended_.push_back(id);
  };
  std::thread thread;
  try {
    thread = std::thread(std::move(run));
  } catch (const std::system_error&) {  // the only way std::thread says so
    return false;
  }
  own_.emplace(id, std::move(thread));
  return true;
}

void Executor::JoinEndedLocked() {
  // Each of these has left own_mu_ for good: joined at once.
  for (uint64_t id : ended_) {
    auto it = own_.find(id);
    if (it == own_.end()) continue;
    it->second.join();
    own_.erase(it);
  }
  ended_.clear();
}

void Executor::Schedule(std::function<void()> task) {
  absl::MutexLock l(&mu_);
  tasks_.push_back(std::move(task));
}

void Executor::Loop() {
  for (;;) {
    std::function<void()> task;
    {
      absl::MutexLock l(&mu_);
      mu_.Await(absl::Condition(
          +[](Executor* e) ABSL_EXCLUSIVE_LOCKS_REQUIRED(e->mu_) {
            return e->stop_ || !e->tasks_.empty();
          },
          this));
      if (tasks_.empty()) return;  // stopping, and nothing left to run
      task = std::move(tasks_.front());
      tasks_.pop_front();
    }
    task();
  }
}

}  // namespace swarf::server

#include "server/executor.h"

#include <algorithm>
#include <exception>

#include "server/logging.h"

namespace radiosity::service {
namespace {

void Log(const char* what) noexcept {
  try {
    LogLine("executor_error").Str("error", what).Error();
  } catch (...) {
  }
}

void RunCaught(const std::function<void()>& task) noexcept {
  try {
    task();
  } catch (const std::exception& e) {
    Log(e.what());
  } catch (...) {
    Log("unknown exception");
  }
}

}  // namespace

Executor::Executor(int threads) {
  for (int i = 0; i < std::max(1, threads); ++i) threads_.emplace_back([this] { Loop(); });
}

Executor::~Executor() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void Executor::Run(std::function<void()> task) noexcept {
  try {
    {
      std::lock_guard<std::mutex> lock(mu_);
      tasks_.push_back(std::move(task));
    }
    cv_.notify_one();
  } catch (...) {
    RunCaught(task);
  }
}

void Executor::Loop() {
  while (true) {
    std::function<void()> task;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return stopping_ || !tasks_.empty(); });
      if (tasks_.empty()) return;  // Stopping, and nothing left to run.
      task = std::move(tasks_.front());
      tasks_.pop_front();
    }
    RunCaught(task);
  }
}

}  // namespace radiosity::service

// A fixed pool of threads for the service's long work (validating an upload, loading and counting
// a scene for CreateJob, removing files), so that gRPC's callback threads only start and finish
// calls: "Reactions must not include blocking operations (such as blocking I/O ...)"
// (grpcpp/support/server_callback.h). Tasks start in the order given, several at a time; no
// exception escapes a task (it is caught and logged).
#ifndef RADIOSITY_SERVER_EXECUTOR_H_
#define RADIOSITY_SERVER_EXECUTOR_H_

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace radiosity::service {

class Executor {
 public:
  // Starts `threads` threads (at least 1).
  explicit Executor(int threads);
  // Runs every task already given, then joins the threads.
  ~Executor();
  Executor(const Executor&) = delete;
  Executor& operator=(const Executor&) = delete;

  // Queues `task`. When it cannot be queued (out of memory) it runs on the calling thread, so a
  // task that finishes an RPC always runs.
  void Run(std::function<void()> task) noexcept;

 private:
  void Loop();

  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_EXECUTOR_H_

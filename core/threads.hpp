// Opt-in threads for the solvers' force pass: a fixed pool behind parallel.hpp's interface
// (plain C++, no instruction-set code), and a solver's share of it attached to its lanes.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "model.hpp"
#include "parallel.hpp"

namespace softbody {

/// A fixed set of worker threads for Parallel: run() hands chunk 0 to the caller
/// and chunk w to worker w, and returns when every chunk is done. Workers wait on a
/// condition variable between calls, so an idle pool costs nothing.
class ThreadPool {
public:
    static constexpr int kMostThreads = 256;

    explicit ThreadPool(int threads) : threads_(threads) {
        for (int w = 1; w < threads; ++w) workers_.emplace_back([this, w] { work(w); });
    }
    ~ThreadPool() {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            stop_ = true;
        }
        start_.notify_all();
        for (std::thread& t : workers_) t.join();
    }
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    Parallel interface() {
        Parallel p;
        p.chunks = threads_;
        p.pool = this;
        p.run = [](const Parallel& self, void (*task)(void*, int), void* context) {
            static_cast<ThreadPool*>(self.pool)->run(task, context);
        };
        return p;
    }

private:
    void run(void (*task)(void*, int), void* context) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            task_ = task;
            context_ = context;
            pending_ = threads_ - 1;
            ++generation_;
        }
        start_.notify_all();
        task(context, 0);
        std::unique_lock<std::mutex> lock(mutex_);
        done_.wait(lock, [this] { return pending_ == 0; });
    }

    void work(int chunk) {
        std::uint64_t seen = 0;
        for (;;) {
            void (*task)(void*, int);
            void* context;
            {
                std::unique_lock<std::mutex> lock(mutex_);
                start_.wait(lock, [&] { return stop_ || generation_ != seen; });
                if (stop_) return;
                seen = generation_;
                task = task_;
                context = context_;
            }
            task(context, chunk);
            {
                std::lock_guard<std::mutex> lock(mutex_);
                --pending_;
            }
            done_.notify_one();
        }
    }

    int threads_;
    std::vector<std::thread> workers_;
    std::mutex mutex_;
    std::condition_variable start_, done_;
    std::uint64_t generation_ = 0;
    int pending_ = 0;
    bool stop_ = false;
    void (*task_)(void*, int) = nullptr;
    void* context_ = nullptr;
};

/// A solver's opt-in threads: a pool, its Parallel interface and the per-chunk volume
/// sums, attached to the solver's force pass (1 thread: nothing, the serial kernels).
/// Lives inside its solver and never moves, since the lanes point at it.
class SolverThreads {
public:
    SolverThreads(int threads, index body_count) {
        if (threads < 1 || threads > ThreadPool::kMostThreads)
            throw std::invalid_argument("threads must be from 1 to " +
                                        std::to_string(ThreadPool::kMostThreads));
        if (threads > 1) {
            pool_ = std::make_unique<ThreadPool>(threads);
            parallel_ = pool_->interface();
            chunk_volume_.assign(static_cast<size_t>(threads * body_count), 0.0);
        }
    }
    SolverThreads(const SolverThreads&) = delete;
    SolverThreads& operator=(const SolverThreads&) = delete;

    void attach(LaneBuffers& lanes) {
        if (!pool_) return;
        lanes.parallel = &parallel_;
        lanes.chunk_volume = chunk_volume_.data();
    }
    int count() const { return parallel_.chunks; }

private:
    std::unique_ptr<ThreadPool> pool_;
    Parallel parallel_;
    std::vector<double> chunk_volume_;
};

}  // namespace softbody

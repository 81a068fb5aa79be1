// A bounded multi-producer / multi-consumer queue joining pipeline stages.
//
// Policies when full: kBlock (Push waits for room: back-pressure) or kDropOldest ("latest
// wins": the oldest item is discarded and counted). Stop() is end of stream: pushes are refused,
// pops drain what is left and then return nullopt. Waits use condition variables (no polling).
//
//   BoundedQueue<Frame> q(2, BoundedQueue<Frame>::Policy::kDropOldest);
//   q.Push(frame);                    // producer
//   while (auto f = q.Pop()) use(*f); // consumer, ends after Stop()
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <utility>

namespace m2s::slam {

template <typename T>
class BoundedQueue {
 public:
  enum class Policy { kBlock, kDropOldest };

  BoundedQueue(size_t capacity, Policy policy)
      : capacity_(capacity < 1 ? 1 : capacity), policy_(policy) {}
  BoundedQueue(const BoundedQueue&) = delete;
  BoundedQueue& operator=(const BoundedQueue&) = delete;

  // False when the queue is stopped (the item is discarded).
  bool Push(T item) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (policy_ == Policy::kBlock) {
      not_full_.wait(lock, [&] { return stopped_ || items_.size() < capacity_; });
    }
    if (stopped_) return false;
    if (items_.size() >= capacity_) {
      items_.pop_front();
      ++dropped_;
    }
    items_.push_back(std::move(item));
    not_empty_.notify_one();
    return true;
  }

  // Blocks until an item arrives; nullopt once stopped and drained.
  std::optional<T> Pop() {
    std::unique_lock<std::mutex> lock(mutex_);
    not_empty_.wait(lock, [&] { return stopped_ || !items_.empty(); });
    return TakeLocked();
  }
  // As Pop(), giving up after timeout_s (nullopt).
  std::optional<T> PopFor(double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_empty_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return stopped_ || !items_.empty(); });
    return TakeLocked();
  }
  std::optional<T> TryPop() {
    std::lock_guard<std::mutex> lock(mutex_);
    return TakeLocked();
  }

  // End of stream: wakes every waiter; later pushes fail.
  void Stop() {
    std::lock_guard<std::mutex> lock(mutex_);
    stopped_ = true;
    not_empty_.notify_all();
    not_full_.notify_all();
  }
  // Discards queued items (returns how many).
  size_t Clear() {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t n = items_.size();
    items_.clear();
    not_full_.notify_all();
    return n;
  }
  // Accepts pushes again after Stop() (the queue is emptied).
  void Restart() {
    std::lock_guard<std::mutex> lock(mutex_);
    items_.clear();
    stopped_ = false;
  }

  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }
  size_t capacity() const { return capacity_; }
  bool full() const { return size() >= capacity_; }
  bool stopped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return stopped_;
  }
  int64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }

 private:
  std::optional<T> TakeLocked() {
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return item;
  }

  const size_t capacity_;
  const Policy policy_;
  mutable std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::deque<T> items_;
  bool stopped_ = false;
  int64_t dropped_ = 0;
};

}  // namespace m2s::slam

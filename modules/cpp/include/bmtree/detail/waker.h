// bmtree C++ basic modules, internal: the Waker, which ends a BM_input's wait for its inputs.
// Part of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_DETAIL_WAKER_H
#define BMTREE_DETAIL_WAKER_H

#include <ros/callback_queue_interface.h>

#include <boost/make_shared.hpp>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

namespace bmtree {
namespace detail {

/// Calls `fn` on a callback queue (the module's, so in its spinner thread) once a deadline has
/// passed: the end of a BM_input's wait for its inputs. A thread of its own, not a ROS timer: it
/// may be set again from any thread, also from inside its own callback.
class Waker {
 public:
  using Clock = std::chrono::steady_clock;

  Waker(ros::CallbackQueueInterface* queue, std::function<void()> fn) : queue_(queue), fn_(std::move(fn)) {
    thread_ = std::thread([this]() { loop(); });
  }
  ~Waker() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      quit_ = true;
    }
    cv_.notify_all();
    thread_.join();
    queue_->removeByID(id());
  }
  Waker(const Waker&) = delete;
  Waker& operator=(const Waker&) = delete;

  /// Call back at `when` (or at an earlier time already set; a call back too early is harmless).
  void at(Clock::time_point when) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (armed_ && at_ <= when) return;
      at_ = when;
      armed_ = true;
    }
    cv_.notify_all();
  }

 private:
  class Call : public ros::CallbackInterface {
   public:
    explicit Call(const std::function<void()>* fn) : fn_(fn) {}
    CallResult call() override {
      (*fn_)();
      return Success;
    }

   private:
    const std::function<void()>* fn_;
  };

  std::uint64_t id() const { return reinterpret_cast<std::uintptr_t>(this); }  // widened, never narrowed

  void loop() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!quit_) {
      if (!armed_) {
        cv_.wait(lock);
      } else if (Clock::now() < at_) {
        cv_.wait_until(lock, at_);
      } else {
        armed_ = false;
        lock.unlock();
        queue_->addCallback(boost::make_shared<Call>(&fn_), id());
        lock.lock();
      }
    }
  }

  ros::CallbackQueueInterface* queue_;
  const std::function<void()> fn_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool armed_ = false;
  bool quit_ = false;
  Clock::time_point at_{};
  std::thread thread_;
};

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_WAKER_H

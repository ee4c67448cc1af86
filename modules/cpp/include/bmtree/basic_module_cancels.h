// bmtree C++ basic modules: how BasicModule cancels a call (its definitions, inline, beside the
// class in basic_module_class.h): BM_cancel in the cancel thread, onCancel() callbacks and
// CancelHook, sleepFor() and callId(), and a call whose caller is gone (the caller watch,
// caller_watch.h). Part of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_BASIC_MODULE_CANCELS_H
#define BMTREE_BASIC_MODULE_CANCELS_H

#include <ros/ros.h>
#include <std_msgs/String.h>

#include <boost/make_shared.hpp>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <exception>
#include <functional>
#include <iterator>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <typeinfo>
#include <utility>

#if defined(__GNUG__)
#include <cxxabi.h>
#endif

#include <nlohmann/json.hpp>

#include "basic_module_class.h"
#include "cancel_hook.h"
#include "detail/task.h"
#include "detail/text.h"

namespace bmtree {

// sleepFor(), callId(), onCancel(): documented in the class (basic_module_class.h)
inline bool BasicModule::sleepFor(double seconds) {
  std::unique_lock<std::mutex> lock(cancel_mutex_);
  auto stop = [this]() { return cancelled(); };
  if (!(seconds > 0)) return !stop();  // also NaN: no wait
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(std::min(seconds, 1e9)));
  while (Clock::now() < end) {  // a shutdown notifies nobody: look at it every 50 ms
    if (cancel_cv_.wait_until(lock, std::min(end, Clock::now() + std::chrono::milliseconds(50)), stop)) {
      return false;
    }
  }
  return !stop();
}

inline std::string BasicModule::callId() const {
  std::lock_guard<std::mutex> lock(cancel_mutex_);
  return running_;
}

inline CancelHook BasicModule::onCancel(std::function<void()> fn) {
  if (!fn) return CancelHook();
  std::unique_lock<std::mutex> lock(cancel_mutex_);
  if (!in_function_) {
    throw std::logic_error("bmtree: onCancel() is for use inside a function (it is about the running call)");
  }
  const std::uint64_t id = ++hook_counter_;
  Hook& hook = hooks_[id];
  hook.fn = std::move(fn);
  if (cancelled_.load()) {  // too late to wait for the cancel: now, here
    hook.due = true;
    runDueHook(lock, id);
  }
  return CancelHook(this, id);
}

/// cancel_mutex_ held: cancel the running call; true if it was not cancelled yet. Every onCancel()
/// callback registered now is due from this moment, decided under the lock that sets cancelled_: the
/// function may see the cancel (sleepFor() returns, cancelled()) and drop its CancelHook before the
/// cancel thread runs the callback, and the callback must run all the same (removeHook() runs it then).
inline bool BasicModule::cancelNow() {
  if (cancelled_.exchange(true)) return false;
  for (auto& h : hooks_) h.second.due = true;
  return true;
}

/// In the cancel thread: cancel the running call, or remember the id of one not started yet.
inline void BasicModule::onCancelMessage(const ros::MessageEvent<std_msgs::String const>& event) {
  std::string id;
  try {
    const std_msgs::String& msg = *event.getConstMessage();
    if (msg.data.size() > kMaxPayload) throw std::runtime_error("payload too large");
    id = nlohmann::json::parse(msg.data).at("call_id").get<std::string>();
  } catch (const std::exception& e) {
    ROS_ERROR("bmtree: ignored a malformed BM_cancel message: %s", e.what());
    return;
  }
  bool now = false;
  std::uint64_t serial = 0;
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    if (in_function_ && !running_.empty() && id == running_) {
      now = cancelNow();
      serial = call_serial_;
    } else {
      if (early_cancels_.size() >= kMaxEarlyCancels) early_cancels_.pop_front();
      early_cancels_.push_back(id);  // it may overtake its BM_input (another connection)
    }
  }
  cancel_cv_.notify_all();
  if (now) runHooks(serial);
}

/// In the cancel thread: each due onCancel() callback of the cancelled call `serial` that no other
/// thread has taken, once, in the order they were registered.
inline void BasicModule::runHooks(std::uint64_t serial) {
  std::unique_lock<std::mutex> lock(cancel_mutex_);
  while (in_function_ && call_serial_ == serial) {  // (that call may have ended meanwhile: its hooks ran then)
    auto it = std::find_if(hooks_.begin(), hooks_.end(), [](const std::pair<const std::uint64_t, Hook>& h) {
      return h.second.due && !h.second.fired;
    });
    if (it == hooks_.end()) return;
    runDueHook(lock, it->first);
  }
}

/// `lock` holds cancel_mutex_: run the due onCancel() callback `id` in this thread unless another
/// thread has taken it (the lock is released while it runs, so that it may call the library); true
/// if it ran here.
inline bool BasicModule::runDueHook(std::unique_lock<std::mutex>& lock, std::uint64_t id) {
  auto it = hooks_.find(id);
  if (it == hooks_.end() || !it->second.due || it->second.fired) return false;
  it->second.fired = it->second.running = true;
  it->second.thread = std::this_thread::get_id();
  const std::function<void()> fn = it->second.fn;
  lock.unlock();
  callHook(fn);
  lock.lock();
  it = hooks_.find(id);
  if (it != hooks_.end()) it->second.running = false;
  cancel_cv_.notify_all();
  return true;
}

inline void BasicModule::callHook(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const std::exception& e) {
    ROS_ERROR("bmtree: an onCancel() callback threw %s: %s", detail::typeName(&typeid(e)).c_str(), e.what());
  } catch (...) {
#if defined(__GNUG__)
    const std::type_info* type = abi::__cxa_current_exception_type();
#else
    const std::type_info* type = nullptr;
#endif
    ROS_ERROR("bmtree: an onCancel() callback threw %s", detail::typeName(type).c_str());
  }
}

/// CancelHook's destructor: forget hook `id`, after it has run if it runs in another thread now. A
/// due one that no thread has taken yet (the call was cancelled, and the function saw it before the
/// cancel thread came to the callback) runs here first: a cancelled call's callbacks always run.
inline void BasicModule::removeHook(std::uint64_t id) {
  std::unique_lock<std::mutex> lock(cancel_mutex_);
  for (;;) {
    auto it = hooks_.find(id);
    if (it == hooks_.end()) return;
    if (it->second.running && it->second.thread != std::this_thread::get_id()) {
      cancel_cv_.wait(lock);  // it runs in the cancel thread: the callback never outlives its hook
    } else if (!runDueHook(lock, id)) {  // (false: the lock was kept, `it` is still good)
      hooks_.erase(it);
      return;
    }
  }
}

/// Mark `call` running (cancels naming it now reach the function); true if it was cancelled
/// before it started.
inline bool BasicModule::startRunning(const Pending& call) {
  bool unconnected = false;
  bool early = false;
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    cancelled_.store(false);
    running_ = call.call_id;
    running_caller_ = call.bridge;
    running_function_ = call.function;
    in_function_ = true;
    ++call_serial_;
    auto seen = out_subscribers_.find(call.bridge);
    unconnected = seen != out_subscribers_.end() && seen->second == 0;  // it left while its call waited
    if (!call.call_id.empty()) {
      auto it = std::find(early_cancels_.begin(), early_cancels_.end(), call.call_id);
      early = it != early_cancels_.end();
      if (early) early_cancels_.erase(it);
    }
  }
  if (unconnected && !early) caller_watch_.check(call.bridge);
  return early;
}

/// The call has returned: true if it was cancelled meanwhile. Its onCancel() callbacks are done
/// first: one still running in the cancel thread is waited for, and a due one that no thread has
/// taken yet (its CancelHook outlives the call, kept in a member) runs here.
inline bool BasicModule::stopRunning() {
  std::unique_lock<std::mutex> lock(cancel_mutex_);
  for (;;) {
    cancel_cv_.wait(lock, [this]() {
      return std::none_of(hooks_.begin(), hooks_.end(),
                          [](const std::pair<const std::uint64_t, Hook>& h) { return h.second.running; });
    });
    auto it = std::find_if(hooks_.begin(), hooks_.end(), [](const std::pair<const std::uint64_t, Hook>& h) {
      return h.second.due && !h.second.fired;
    });
    if (it == hooks_.end()) break;
    runDueHook(lock, it->first);
  }
  hooks_.clear();
  in_function_ = false;
  running_.clear();
  running_caller_.clear();
  running_function_.clear();
  return cancelled_.exchange(false);
}

/// In the cancel thread: a node connected to BM_output (a bridge, a tool): remember it, and let the
/// caller watch learn which process it is.
inline void BasicModule::onOutputConnect(const ros::SingleSubscriberPublisher& link) {
  const std::string node = link.getSubscriberName();
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    if (out_subscribers_.size() >= kMaxSubscribers && out_subscribers_.find(node) == out_subscribers_.end()) {
      for (auto it = out_subscribers_.begin(); it != out_subscribers_.end();) {  // forget those gone
        it = it->second == 0 ? out_subscribers_.erase(it) : std::next(it);
      }
    }
    ++out_subscribers_[node];
  }
  caller_watch_.learn(node);
}

/// In the cancel thread: a node's connection to BM_output dropped. If the running call is its, the
/// caller watch asks whether its process is gone (callerGone() then cancels the call).
inline void BasicModule::onOutputDisconnect(const ros::SingleSubscriberPublisher& link) {
  if (!ros::ok()) return;  // the node shuts down: it drops every connection itself
  const std::string node = link.getSubscriberName();
  bool check = false;
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    auto it = out_subscribers_.find(node);
    if (it != out_subscribers_.end() && it->second > 0) --it->second;
    check = (it == out_subscribers_.end() || it->second == 0) && in_function_ && running_caller_ == node &&
            !cancelled_.load();
  }
  if (check) caller_watch_.check(node);
}

/// The caller watch's question (its thread): is a call of `node` running while `node` has no
/// connection to BM_output?
inline bool BasicModule::callerWanted(const std::string& node) {
  std::lock_guard<std::mutex> lock(cancel_mutex_);
  if (!ros::ok() || !in_function_ || running_caller_ != node || cancelled_.load()) return false;
  auto it = out_subscribers_.find(node);
  return it == out_subscribers_.end() || it->second == 0;
}

/// The caller watch found `node`'s process gone (its thread): cancel its call in the cancel thread,
/// where onCancel() callbacks run.
inline void BasicModule::callerGone(const std::string& node, const std::string& reason) {
  cancel_queue_.addCallback(boost::make_shared<detail::Task>([this, node, reason]() { cancelCallOf(node, reason); }));
}

/// In the cancel thread: cancel the running call of `node`, whose process is gone, as a BM_cancel
/// would (nobody can take its answer; running on, it would drive the hardware and hold the module).
inline void BasicModule::cancelCallOf(const std::string& node, const std::string& reason) {
  bool now = false;
  std::uint64_t serial = 0;
  std::string id, function;
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    if (!in_function_ || running_caller_ != node || cancelled_.load()) return;  // ended, or cancelled already
    serial = call_serial_;
    id = running_.empty() ? std::string("(no call id)") : running_;
    function = running_function_;
    // said before the function can see it, so that the log reads in order
    ROS_WARN("bmtree: cancelled call %s of %s.%s: its caller %s is gone (%s)", id.c_str(), module_.c_str(),
             function.c_str(), node.c_str(), reason.c_str());
    now = cancelNow();
  }
  cancel_cv_.notify_all();
  if (now) runHooks(serial);
}

inline void CancelHook::reset() {
  if (owner_ != nullptr) owner_->removeHook(id_);
  owner_ = nullptr;
}

}  // namespace bmtree

#endif  // BMTREE_BASIC_MODULE_CANCELS_H

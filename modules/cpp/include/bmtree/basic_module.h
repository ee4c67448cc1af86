// bmtree C++ basic modules: a module is a class with one method per function.
//
// Speaks the original C++ basic-module protocol (manual section 4.3) to a bridge node
// (bmtree-bridge, or the original one): data topics /<BM>/<type> carry the values,
// /<BM>/BM_input and /<BM>/BM_output synchronise. Header-only, C++14, no sleeps, no
// rospack at run time.
//
//   class Gripper : public bmtree::BasicModule {
//    public:
//     explicit Gripper(ros::NodeHandle nh) : BasicModule(nh, "gripper") {
//       provide("set_fingers", &Gripper::setFingers, {"opening", "success"});
//     }
//     std::tuple<std_msgs::Float64, std_msgs::Bool> setFingers(const std_msgs::Float64& left,
//                                                             const std_msgs::Float64& right);
//   };
//   int main(int argc, char** argv) { return bmtree::run<Gripper>(argc, argv, "gripper"); }
//
// Threads: a function runs in the thread that spins the node's callback queue (with run(): the
// main thread, inside ros::spin()), one call at a time. While it runs, that thread runs no other
// callback of the queue: your own subscriptions and timers on it wait until the function has
// returned. Do not call ros::spinOnce() inside a function (the library's own callbacks that it would
// run are put off until the function returns); give your own topics a ros::CallbackQueue of their
// own (spin it with callAvailable(), or an AsyncSpinner). Service calls and publishing are fine,
// except a call to a service this node serves on the queue the function holds (it cannot answer).
// A custom main() with a MultiThreadedSpinner or AsyncSpinner on the global queue works too: the
// library still runs one function at a time (a BM_input that arrives meanwhile waits for it).
//
// What it does beyond the original utility: its inputs are only the data messages of the node
// that sent BM_input (connection header callerid: not its own outputs, not a third node's);
// the i-th such message received on a topic for a call is the i-th
// input listed on that topic, so two inputs of one type keep their values; a BM_input that
// overtook its inputs waits for them, bounded by ~input_wait (1 s). A call of bmtree-bridge
// (it carries a call_id) whose inputs did not all arrive is answered "failed" naming them, without
// running the function; a call of the original bridge runs with the last values received, as the
// original did, and a warning names the stale inputs. A function that throws bmtree::Failure /
// bmtree::Rejected (or any exception) answers BM_output with "error" and "status" keys, which
// bmtree-bridge reports and the original bridge ignores; other exceptions are logged with their
// type. An unknown function is answered with an error instead of silence; /<BM>/BM_info (latched)
// tells a bridge that this library is on the other side, so it needs no gap between the inputs and
// BM_input.
//
// Cancels: a bridge that gives up on a call (the tree halted it, or its --call-timeout passed)
// publishes {"call_id": ...} on /<BM>/BM_cancel. That topic is served by a thread of its own, so
// a cancel arrives while the function runs: a long function polls cancelled(), waits with
// sleepFor(seconds), or registers onCancel(callback), stops the hardware and returns; its answer then
// says "cancelled" (the bridge throws its outputs away) and the module takes calls again at once. A
// call cancelled before it started is answered "cancelled" without running. The original bridge
// sends no cancels. A call whose caller is gone (the bridge was killed: its connection to BM_output
// dropped, and its XML-RPC port refuses or answers with another pid) is cancelled the same way, and
// the node logs it ("cancelled call ... of arm.move_to: its caller /arm_bridge is gone (...)").
//
// Events: emit() publishes an event of the module's definition ("Events"), from any thread (a
// ros::Timer, a subscriber's callback, a thread of your own, a function while it runs):
//
//   std_msgs::String name;  name.data = "Ana";
//   geometry_msgs::Point where;  where.x = 1.0;
//   emit("personSeen", {{"name", name}, {"position", where}});   // false if it could not be sent
//
// Each param is a ROS message (bmtree::EventParam: a name and any message type; a double or a
// char* does not compile), serialized at once. The event travels as one message on
// /<BM>/BM_event (std_msgs/String: JSON with the event's name and, per param, its name, ROS type,
// md5sum and serialized bytes in base64), never on the data topics, so it cannot be taken for a
// call's output. bmtree-bridge checks it against the definition (unknown event or param, missing
// param, another type: it logs a warning naming this node and drops it) and publishes it as a bmtree
// event, which a tree's wait_event takes. Nothing is sent while no bridge is connected.
//
// A restarted ROS master is survived (master_watch.h): the module registers its topics again.
// stdout is line-buffered, so that prints reach a log file as they happen.
#ifndef BMTREE_BASIC_MODULE_H
#define BMTREE_BASIC_MODULE_H

/// The library's API level, for a module that must also build against older copies (#if
/// BMTREE_CPP_API >= 3): 2 added onCancel(), callId(), and made cancelled() and sleepFor() public;
/// 3 added emit() and bmtree::EventParam (events on /<BM>/BM_event), and cancels a call whose
/// caller's process is gone.
#define BMTREE_CPP_API 3

#include <ros/message_traits.h>
#include <ros/ros.h>
#include <ros/serialization.h>
#include <std_msgs/String.h>

#include <ros/callback_queue.h>
#include <ros/callback_queue_interface.h>

#include <boost/make_shared.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <functional>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <typeinfo>
#include <utility>
#include <vector>

#if defined(__GNUG__)
#include <cxxabi.h>
#endif

#include <nlohmann/json.hpp>

#include "master_watch.h"

namespace bmtree {

/// Throw from a function to answer "failed" with a reason.
class Failure : public std::runtime_error {
 public:
  explicit Failure(const std::string& what) : std::runtime_error(what) {}
};

/// Throw from a function to answer "rejected": the call cannot be taken now.
class Rejected : public std::runtime_error {
 public:
  explicit Rejected(const std::string& what) : std::runtime_error(what) {}
};

/// The data topic of a ROS type in module `module`: "std_msgs/Float64" -> "/module/float64".
inline std::string dataTopic(const std::string& module, const std::string& datatype) {
  std::string base = datatype.substr(datatype.rfind('/') + 1);
  for (char& c : base) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return "/" + module + "/" + base;
}

class BasicModule;

/// What onCancel() returns: the callback stays registered while this object lives (at most until
/// the call ends). Keep it in a local variable declared after what the callback uses: its
/// destructor unregisters the callback and waits for it if it is running, so the callback never
/// sees those objects destroyed.
class CancelHook {
 public:
  CancelHook() = default;
  CancelHook(CancelHook&& other) noexcept : owner_(other.owner_), id_(other.id_) { other.owner_ = nullptr; }
  CancelHook& operator=(CancelHook&& other) noexcept {
    if (this != &other) {
      reset();
      owner_ = other.owner_;
      id_ = other.id_;
      other.owner_ = nullptr;
    }
    return *this;
  }
  CancelHook(const CancelHook&) = delete;
  CancelHook& operator=(const CancelHook&) = delete;
  ~CancelHook() { reset(); }
  /// Unregister the callback now (waits for it if it is running in another thread).
  inline void reset();

 private:
  friend class BasicModule;
  CancelHook(BasicModule* owner, std::uint64_t id) : owner_(owner), id_(id) {}
  BasicModule* owner_ = nullptr;
  std::uint64_t id_ = 0;
};

namespace detail {

/// A module's output mostly goes to a log file (roslaunch, systemd), where stdout is
/// block-buffered: prints (ROS_INFO too) would show up kilobytes late, or never after a kill.
/// Set before main(), so before any output.
inline bool lineBufferedStdout() { return std::setvbuf(stdout, nullptr, _IOLBF, 0) == 0; }
static const bool kStdoutLineBuffered = lineBufferedStdout();

/// The readable name of a type: "std::runtime_error", not "St13runtime_error".
inline std::string typeName(const std::type_info* type) {
  if (type == nullptr) return "an unknown type";
#if defined(__GNUG__)
  int status = 0;
  char* name = abi::__cxa_demangle(type->name(), nullptr, nullptr, &status);
  if (status == 0 && name != nullptr) {
    std::string out(name);
    std::free(name);
    return out;
  }
  std::free(name);
#endif
  return type->name();
}

/// Standard base64 (RFC 4648, with padding) of `n` bytes.
inline std::string base64(const std::uint8_t* data, std::size_t n) {
  static const char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((n + 2) / 3 * 4);
  for (std::size_t i = 0; i < n; i += 3) {
    const std::uint32_t b0 = data[i];
    const std::uint32_t b1 = i + 1 < n ? data[i + 1] : 0u;
    const std::uint32_t b2 = i + 2 < n ? data[i + 2] : 0u;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kDigits[(v >> 18) & 63u];
    out += kDigits[(v >> 12) & 63u];
    out += i + 1 < n ? kDigits[(v >> 6) & 63u] : '=';
    out += i + 2 < n ? kDigits[v & 63u] : '=';
  }
  return out;
}

/// A function to run on a callback queue (the cancel thread's, for the caller watch).
class Task : public ros::CallbackInterface {
 public:
  explicit Task(std::function<void()> fn) : fn_(std::move(fn)) {}
  CallResult call() override {
    fn_();
    return Success;
  }

 private:
  std::function<void()> fn_;
};

/// "1", "0.3": seconds as a person writes them.
inline std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

/// One data topic: publisher, subscriber, and the messages received for the next call. The data
/// is guarded by the module's state mutex (callbacks may come from several spinner threads).
class ChannelBase {
 public:
  virtual ~ChannelBase() = default;
  /// Messages from `publisher` received since the last call took its inputs (mutex held).
  virtual std::size_t fresh(const std::string& publisher) const = 0;
  /// Select `n` values from `publisher` for a call (its last `n` fresh ones, the last value
  /// received for any missing), and forget the fresh messages (mutex held).
  virtual void select(std::size_t n, const std::string& publisher) = 0;
};

template <class M>
class Channel : public ChannelBase {
 public:
  Channel(ros::NodeHandle& nh, const std::string& topic, std::mutex& mutex, std::function<void()> on_data)
      : mutex_(mutex), on_data_(std::move(on_data)) {
    pub_ = nh.advertise<M>(topic, 100);
    sub_ = nh.subscribe(topic, 100, &Channel::onMessage, this, ros::TransportHints().tcpNoDelay());
  }

  std::size_t fresh(const std::string& publisher) const override {
    std::size_t n = 0;
    for (const auto& f : fresh_) {
      if (f.first == publisher) ++n;
    }
    return n;
  }

  void select(std::size_t n, const std::string& publisher) override {
    std::vector<M> mine;
    for (const auto& f : fresh_) {
      if (f.first == publisher) mine.push_back(f.second);
    }
    selected_.clear();
    std::size_t skip = mine.size() > n ? mine.size() - n : 0;
    for (std::size_t i = skip; i < mine.size(); ++i) selected_.push_back(mine[i]);
    while (selected_.size() < n) selected_.push_back(last_);
    fresh_.clear();
  }

  /// The i-th selected value: read by the running function's thread only.
  const M& selected(std::size_t i) const { return selected_.at(i); }

  void publish(const M& msg) const { pub_.publish(msg); }

 private:
  void onMessage(const ros::MessageEvent<M const>& event) {
    if (event.getPublisherName() == ros::this_node::getName()) return;  // our own output
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const M& msg = *event.getConstMessage();
      last_ = msg;
      if (fresh_.size() >= kMaxFresh) fresh_.pop_front();
      fresh_.emplace_back(event.getPublisherName(), msg);
    }
    on_data_();
  }

  static constexpr std::size_t kMaxFresh = 64;
  std::mutex& mutex_;
  std::function<void()> on_data_;
  ros::Publisher pub_;
  ros::Subscriber sub_;
  std::deque<std::pair<std::string, M>> fresh_;  // (publisher, message)
  std::vector<M> selected_;
  M last_{};
};

template <class M>
std::string datatypeOf() {
  return ros::message_traits::DataType<M>::value();
}

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

/// One parameter of an event for BasicModule::emit(): its name (the definition's Event-params Name)
/// and its value, any ROS message (std_msgs::String, geometry_msgs::Point, a message of yours),
/// serialized when the EventParam is made:  emit("personSeen", {{"name", name}, {"position", where}});
class EventParam {
 public:
  template <class M>
  EventParam(std::string name, const M& value) : name_(std::move(name)) {
    static_assert(ros::message_traits::IsMessage<M>::value,
                  "bmtree::EventParam: an event param's value must be a ROS message (std_msgs::Float64, not double; "
                  "std_msgs::String, not const char*)");
    type_ = ros::message_traits::DataType<M>::value();
    md5sum_ = ros::message_traits::MD5Sum<M>::value();
    const std::uint32_t size = ros::serialization::serializationLength(value);
    std::vector<std::uint8_t> bytes(size);
    ros::serialization::OStream out(bytes.data(), size);
    ros::serialization::serialize(out, value);
    data_ = detail::base64(bytes.data(), bytes.size());
  }

  const std::string& name() const { return name_; }
  /// Its ROS type, "geometry_msgs/Point".
  const std::string& type() const { return type_; }

 private:
  friend class BasicModule;
  std::string name_;
  std::string type_;
  std::string md5sum_;
  std::string data_;  // the serialized message, base64
};

/// Base class of a C++ basic module. Register functions with provide() in the constructor.
class BasicModule {
 public:
  using Clock = std::chrono::steady_clock;

  BasicModule(ros::NodeHandle nh, const std::string& module) : nh_(nh) {
    ros::NodeHandle("~").param<std::string>("basic_mod", module_, module);
    ros::NodeHandle("~").param<double>("input_wait", input_wait_, 1.0);
    if (!(input_wait_ >= 0) || input_wait_ > 3600) input_wait_ = 1.0;  // NaN, negative, absurd
    caller_watch_.start();
    // cancels (and a caller's lost connection) must get through while a function blocks the node's
    // spinner thread: the cancel thread's queue
    ros::NodeHandle cancel_nh(nh_);
    cancel_nh.setCallbackQueue(&cancel_queue_);
    out_pub_ = cancel_nh.advertise<std_msgs::String>(
        "/" + module_ + "/BM_output", 10, [this](const ros::SingleSubscriberPublisher& s) { onOutputConnect(s); },
        [this](const ros::SingleSubscriberPublisher& s) { onOutputDisconnect(s); });
    info_pub_ = nh_.advertise<std_msgs::String>("/" + module_ + "/BM_info", 1, true);
    event_pub_ = nh_.advertise<std_msgs::String>("/" + module_ + "/BM_event", 100);
    waker_.reset(new detail::Waker(nh_.getCallbackQueue(), [this]() { runReady(); }));
    in_sub_ = nh_.subscribe("/" + module_ + "/BM_input", 10, &BasicModule::onInput, this,
                            ros::TransportHints().tcpNoDelay());
    cancel_sub_ = cancel_nh.subscribe("/" + module_ + "/BM_cancel", 10, &BasicModule::onCancelMessage, this,
                                      ros::TransportHints().tcpNoDelay());
    cancel_spinner_.reset(new ros::AsyncSpinner(1, &cancel_queue_));
    cancel_spinner_->start();
    publishInfo();
    master_watch_.start();
  }
  virtual ~BasicModule() {
    caller_watch_.stop();
    cancel_spinner_->stop();
    out_pub_.shutdown();  // its connection callbacks go to cancel_queue_, which goes before it
    cancel_sub_.shutdown();
    in_sub_.shutdown();
    waker_.reset();
  }
  BasicModule(const BasicModule&) = delete;
  BasicModule& operator=(const BasicModule&) = delete;

  /// The module's name: the one given to the constructor, or the one of a `_basic_mod:=NAME`
  /// argument (its topics are /<name>/...).
  const std::string& moduleName() const { return module_; }

  /// Publish the event `event` of the module's definition with these params (each a name and a ROS
  /// message), from any thread, also while a function runs:
  ///   emit("personSeen", {{"name", name}, {"position", where}});
  /// The bridge checks it against the definition's Events (the event, each param's name and type)
  /// and logs a warning for one it cannot take. False (and an error in the log) if it could not be
  /// sent: no event name, a param without a name or given twice, or over 1 MiB as a whole.
  bool emit(const std::string& event, std::initializer_list<EventParam> params = {}) const {
    return emit(event, std::vector<EventParam>(params));
  }
  /// The same, with params gathered at run time.
  bool emit(const std::string& event, const std::vector<EventParam>& params) const {
    if (event.empty()) {
      ROS_ERROR("bmtree: emit(): an event needs a name; nothing sent");
      return false;
    }
    nlohmann::json j;
    j["event"] = event;
    j["params"] = nlohmann::json::array();
    std::set<std::string> names;
    for (const auto& p : params) {
      if (p.name_.empty() || !names.insert(p.name_).second) {
        const std::string why = p.name_.empty() ? "a param has no name" : "param '" + p.name_ + "' is given twice";
        ROS_ERROR("bmtree: emit(\"%s\"): %s; nothing sent", event.c_str(), why.c_str());
        return false;
      }
      j["params"].push_back({{"name", p.name_}, {"type", p.type_}, {"md5sum", p.md5sum_}, {"data", p.data_}});
    }
    std_msgs::String msg;
    msg.data = j.dump();
    if (msg.data.size() > kMaxPayload) {
      ROS_ERROR("bmtree: emit(\"%s\"): the event is %zu bytes, over the %zu the bridge takes; nothing sent",
                event.c_str(), msg.data.size(), kMaxPayload);
      return false;
    }
    event_pub_.publish(msg);
    return true;
  }

  /// True once the running call was cancelled, or the node is shutting down (Ctrl-C, rosnode
  /// kill: a respawned node must not drive the hardware beside this one): stop and return.
  /// Thread-safe: a helper object of the function may poll it from any thread.
  bool cancelled() const { return cancelled_.load() || !ros::ok(); }

  /// Wait `seconds` unless the running call is cancelled (or the node shuts down) first; true if
  /// the whole time passed. Use it instead of sleeping, so that a halted tree stops the function
  /// at once.
  bool sleepFor(double seconds) {
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

  /// The call_id of the running call ("" outside a function, and for calls of the original
  /// bridge, which sends none).
  std::string callId() const {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    return running_;
  }

  /// Inside a function: call `fn` once when the running call is cancelled, in the library's cancel
  /// thread (the one that receives BM_cancel), while the function itself goes on running in its own
  /// thread: make what `fn` touches safe to use from two threads (an atomic, a mutex, a driver's
  /// thread-safe stop), and return promptly (the call's answer waits for it). If the call is
  /// cancelled already, `fn` runs at once, in the calling thread. Not called for a call that ends
  /// uncancelled, nor on shutdown (poll cancelled() for that). Keep the returned CancelHook while
  /// `fn` may run:
  ///   bmtree::CancelHook hook = onCancel([this]() { driver_.halt(); });
  /// Outside a function it throws std::logic_error.
#if defined(__GNUG__)
  __attribute__((warn_unused_result))
#endif
  CancelHook onCancel(std::function<void()> fn) {
    if (!fn) return CancelHook();
    std::unique_lock<std::mutex> lock(cancel_mutex_);
    if (!in_function_) {
      throw std::logic_error("bmtree: onCancel() is for use inside a function (it is about the running call)");
    }
    const std::uint64_t id = ++hook_counter_;
    Hook& hook = hooks_[id];
    hook.fn = std::move(fn);
    if (cancelled_.load()) {  // too late to wait for the cancel: now, here
      hook.fired = hook.running = true;
      hook.thread = std::this_thread::get_id();
      std::function<void()> now = hook.fn;
      lock.unlock();
      callHook(now);
      lock.lock();
      auto it = hooks_.find(id);
      if (it != hooks_.end()) it->second.running = false;
      lock.unlock();
      cancel_cv_.notify_all();
    }
    return CancelHook(this, id);
  }

 protected:
  /// Register `fn` as the function `name`; its inputs are its parameters, in the definition's
  /// order; its outputs are the returned tuple's elements, named by `output_names`.
  template <class C, class... Out, class... In>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...),
               const std::array<std::string, sizeof...(Out)>& output_names) {
    C* self = static_cast<C*>(this);
    std::vector<std::string> names(output_names.begin(), output_names.end());
    for (const auto& n : names) {  // {"width"} for two outputs compiles: the missing name is ""
      if (n.empty()) {
        throw std::logic_error("provide(\"" + name + "\"): the function returns " + std::to_string(sizeof...(Out)) +
                               " outputs, so it needs " + std::to_string(sizeof...(Out)) +
                               " non-empty output names");
      }
    }
    std::lock_guard<std::mutex> lock(state_mutex_);
    Function f;
    f.input_topics = {topicFor<In>()...};
    std::vector<std::string> output_topics = {topicFor<Out>()...};
    f.output_names = names;
    f.output_topics = output_topics;
    f.run = [this, self, fn, names, output_topics](const std::vector<std::size_t>& occurrence) {
      std::tuple<Out...> out = invoke(self, fn, occurrence, std::index_sequence_for<In...>());
      publishAll(out, std::index_sequence_for<Out...>());
      nlohmann::json reply;
      reply["outparam_names"] = names;
      reply["outparam_topics"] = output_topics;
      return reply;
    };
    functions_[name] = std::move(f);
    publishInfo();
  }

 private:
  friend class CancelHook;

  struct Function {
    std::vector<std::string> input_topics;
    std::vector<std::string> output_names;
    std::vector<std::string> output_topics;
    std::function<nlohmann::json(const std::vector<std::size_t>&)> run;
  };
  struct Pending {
    std::string function;
    std::vector<std::string> topics;
    std::vector<std::string> names;  // the inputs' names (bmtree-bridge sends them), for messages
    std::string bridge;   // the node that sent BM_input: only its data messages are inputs
    std::string call_id;  // sent by bmtree-bridge (not by the original): what a cancel names
    bool waiting = false;  // its wait for its inputs has begun (it was first at an idle module)
    Clock::time_point deadline{};
  };
  struct Hook {
    std::function<void()> fn;
    bool fired = false;
    bool running = false;
    std::thread::id thread;
  };

  template <class M>
  std::string topicFor() {  // state_mutex_ held
    std::string topic = dataTopic(module_, detail::datatypeOf<M>());
    auto it = channels_.find(topic);
    if (it == channels_.end()) {
      channels_[topic] = std::unique_ptr<detail::ChannelBase>(
          new detail::Channel<M>(nh_, topic, state_mutex_, [this]() { runReady(); }));
      types_[topic] = detail::datatypeOf<M>();
    } else if (types_[topic] != detail::datatypeOf<M>()) {
      throw std::logic_error("types " + types_[topic] + " and " + detail::datatypeOf<M>() +
                             " would share the data topic " + topic);
    }
    return topic;
  }

  template <class M>
  detail::Channel<M>& channel() {
    return static_cast<detail::Channel<M>&>(*channels_.at(dataTopic(module_, detail::datatypeOf<M>())));
  }

  template <class C, class... Out, class... In, std::size_t... I>
  std::tuple<Out...> invoke(C* self, std::tuple<Out...> (C::*fn)(const In&...),
                            const std::vector<std::size_t>& occurrence, std::index_sequence<I...>) {
    (void)occurrence;  // unused when the function has no inputs
    return (self->*fn)(channel<In>().selected(occurrence[I])...);
  }

  template <class... Out, std::size_t... I>
  void publishAll(const std::tuple<Out...>& out, std::index_sequence<I...>) {
    int expand[] = {0, (channel<Out>().publish(std::get<I>(out)), 0)...};
    (void)expand;
  }

  void publishInfo() {
    nlohmann::json info;
    info["library"] = "bmtree";
    info["protocol"] = 3;  // 2: takes cancels on /<BM>/BM_cancel; 3: emits events on /<BM>/BM_event
    info["api"] = BMTREE_CPP_API;
    std::vector<std::string> names;
    nlohmann::json signatures = nlohmann::json::object();
    for (const auto& f : functions_) {
      names.push_back(f.first);
      signatures[f.first] = {{"inparam_topics", f.second.input_topics},
                             {"outparam_names", f.second.output_names},
                             {"outparam_topics", f.second.output_topics}};
    }
    info["functions"] = names;
    info["signatures"] = signatures;  // a bridge checks its definition against them at start
    std_msgs::String msg;
    msg.data = info.dump();
    info_pub_.publish(msg);
  }

  void onInput(const ros::MessageEvent<std_msgs::String const>& event) {
    const std_msgs::String& msg = *event.getConstMessage();
    Pending p;
    p.bridge = event.getPublisherName();
    try {
      if (msg.data.size() > kMaxPayload) throw std::runtime_error("payload too large");
      nlohmann::json j = nlohmann::json::parse(msg.data);
      p.function = j.at("function").get<std::string>();
      p.topics = j.at("inparam_topics").get<std::vector<std::string>>();
      auto id = j.find("call_id");
      if (id != j.end() && id->is_string()) p.call_id = id->get<std::string>();
      auto names = j.find("inparam_names");
      if (names != j.end() && names->is_array() && names->size() == p.topics.size() &&
          std::all_of(names->begin(), names->end(), [](const nlohmann::json& n) { return n.is_string(); })) {
        p.names = names->get<std::vector<std::string>>();
      }
    } catch (const std::exception& e) {
      ROS_ERROR("bmtree: ignored a malformed BM_input message: %s", e.what());
      return;
    }
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      pending_.push_back(std::move(p));
    }
    runReady();
  }

  /// In the cancel thread: cancel the running call, or remember the id of one not started yet.
  void onCancelMessage(const ros::MessageEvent<std_msgs::String const>& event) {
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
        now = !cancelled_.exchange(true);
        serial = call_serial_;
      } else {
        if (early_cancels_.size() >= kMaxEarlyCancels) early_cancels_.pop_front();
        early_cancels_.push_back(id);  // it may overtake its BM_input (another connection)
      }
    }
    cancel_cv_.notify_all();
    if (now) runHooks(serial);
  }

  /// In the cancel thread: each onCancel() callback of the cancelled call `serial`, once.
  void runHooks(std::uint64_t serial) {
    for (;;) {
      std::function<void()> fn;
      std::uint64_t id = 0;
      {
        std::lock_guard<std::mutex> lock(cancel_mutex_);
        if (!in_function_ || call_serial_ != serial) return;  // that call has ended meanwhile
        for (auto& h : hooks_) {
          if (!h.second.fired) {
            h.second.fired = h.second.running = true;
            h.second.thread = std::this_thread::get_id();
            fn = h.second.fn;
            id = h.first;
            break;
          }
        }
      }
      if (id == 0) return;
      callHook(fn);
      {
        std::lock_guard<std::mutex> lock(cancel_mutex_);
        auto it = hooks_.find(id);
        if (it != hooks_.end()) it->second.running = false;
      }
      cancel_cv_.notify_all();
    }
  }

  void callHook(const std::function<void()>& fn) {
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

  /// CancelHook's destructor: forget hook `id`, after it has run if it runs in another thread now.
  void removeHook(std::uint64_t id) {
    std::unique_lock<std::mutex> lock(cancel_mutex_);
    cancel_cv_.wait(lock, [this, id]() {
      auto it = hooks_.find(id);
      return it == hooks_.end() || !it->second.running || it->second.thread == std::this_thread::get_id();
    });
    hooks_.erase(id);
  }

  /// Mark `call` running (cancels naming it now reach the function); true if it was cancelled
  /// before it started.
  bool startRunning(const Pending& call) {
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

  /// The call has returned: true if it was cancelled meanwhile.
  bool stopRunning() {
    std::unique_lock<std::mutex> lock(cancel_mutex_);
    cancel_cv_.wait(lock, [this]() {  // an onCancel() callback still running in the cancel thread
      return std::none_of(hooks_.begin(), hooks_.end(),
                          [](const std::pair<const std::uint64_t, Hook>& h) { return h.second.running; });
    });
    hooks_.clear();
    in_function_ = false;
    running_.clear();
    running_caller_.clear();
    running_function_.clear();
    return cancelled_.exchange(false);
  }

  /// In the cancel thread: a node connected to BM_output (a bridge, a tool): remember it, and let the
  /// caller watch learn which process it is.
  void onOutputConnect(const ros::SingleSubscriberPublisher& link) {
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
  void onOutputDisconnect(const ros::SingleSubscriberPublisher& link) {
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
  bool callerWanted(const std::string& node) {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    if (!ros::ok() || !in_function_ || running_caller_ != node || cancelled_.load()) return false;
    auto it = out_subscribers_.find(node);
    return it == out_subscribers_.end() || it->second == 0;
  }

  /// The caller watch found `node`'s process gone (its thread): cancel its call in the cancel thread,
  /// where onCancel() callbacks run.
  void callerGone(const std::string& node, const std::string& reason) {
    cancel_queue_.addCallback(boost::make_shared<detail::Task>([this, node, reason]() { cancelCallOf(node, reason); }));
  }

  /// In the cancel thread: cancel the running call of `node`, whose process is gone, as a BM_cancel
  /// would (nobody can take its answer; running on, it would drive the hardware and hold the module).
  void cancelCallOf(const std::string& node, const std::string& reason) {
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
      now = !cancelled_.exchange(true);
    }
    cancel_cv_.notify_all();
    if (now) runHooks(serial);
  }

  /// What runReady() hands to execute(): a call whose inputs are selected.
  struct Ready {
    Pending call;
    bool known = false;
    Function function;
    std::vector<std::size_t> missing;  // positions of the inputs that did not arrive in time
  };

  /// Run the pending calls in order, each once its inputs arrived or its wait for them is over.
  /// Any thread (the spinner's, also re-entered through a ros::spinOnce() inside a function, or
  /// several of a multi-threaded spinner): while one function runs, the others only queue.
  void runReady() {
    for (;;) {
      Ready ready;
      Clock::time_point wake_at{};
      bool wake = false;
      {
        std::lock_guard<std::mutex> lock(state_mutex_);
        if (executing_ || pending_.empty()) return;  // the running function's thread goes on here after it
        Pending& p = pending_.front();
        std::map<std::string, std::size_t> count;
        for (const auto& t : p.topics) ++count[t];
        std::map<std::string, std::size_t> got;
        bool complete = true;
        for (const auto& c : count) {
          auto it = channels_.find(c.first);
          got[c.first] = it != channels_.end() ? it->second->fresh(p.bridge) : c.second;
          if (got[c.first] < c.second) complete = false;
        }
        const Clock::time_point now = Clock::now();
        if (!complete) {
          if (!p.waiting) {
            p.waiting = true;
            p.deadline = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(input_wait_));
          }
          if (now < p.deadline) {
            wake = true;
            wake_at = p.deadline;
          }
        }
        if (!wake) {
          ready.call = std::move(pending_.front());
          pending_.pop_front();
          std::map<std::string, std::size_t> seen;
          for (std::size_t i = 0; i < ready.call.topics.size(); ++i) {
            const std::string& t = ready.call.topics[i];
            if (seen[t]++ >= got[t]) ready.missing.push_back(i);  // the k-th value of a topic came if k < got
          }
          for (const auto& c : count) {  // its inputs are spent, whatever happens to the call
            auto it = channels_.find(c.first);
            if (it != channels_.end()) it->second->select(c.second, ready.call.bridge);
          }
          auto f = functions_.find(ready.call.function);
          ready.known = f != functions_.end();
          if (ready.known) ready.function = f->second;
          executing_ = true;
        }
      }
      if (wake) {
        waker_->at(wake_at);
        return;
      }
      execute(ready);
      std::lock_guard<std::mutex> lock(state_mutex_);
      executing_ = false;
    }
  }

  /// "input 'target'", "inputs 'target', 'duration'", "input 2 (on /arm/float64)".
  static std::string inputsNamed(const Pending& call, const std::vector<std::size_t>& positions) {
    std::string out = positions.size() == 1 ? "input " : "inputs ";
    for (std::size_t k = 0; k < positions.size(); ++k) {
      const std::size_t i = positions[k];
      if (k > 0) out += ", ";
      if (i < call.names.size()) {
        out += "'" + call.names[i] + "'";
      } else {
        out += std::to_string(i + 1) + " (on " + call.topics.at(i) + ")";
      }
    }
    return out;
  }

  static std::string callName(const Pending& call) {
    return call.function + (call.call_id.empty() ? std::string(" (no call id)") : " (call " + call.call_id + ")");
  }

  void execute(const Ready& ready) {
    const Pending& call = ready.call;
    nlohmann::json reply;
    if (startRunning(call)) {
      reply = failure("cancelled", "cancelled before it started");
    } else if (!ready.known) {
      reply = failure("rejected", "module " + module_ + " has no function " + call.function);
    } else if (call.topics != ready.function.input_topics) {
      reply = failure("rejected", "function " + call.function + " takes its inputs on " +
                                      nlohmann::json(ready.function.input_topics).dump() + ", not " +
                                      nlohmann::json(call.topics).dump());
    } else if (!ready.missing.empty() && !call.call_id.empty()) {
      // never run a function (a motion) on the previous call's values or on zero messages
      const std::string error = inputsNamed(call, ready.missing) + " did not arrive within input_wait (" +
                                detail::seconds(input_wait_) + "s): " + call.function + " was not run";
      ROS_WARN("bmtree: %s: %s", callName(call).c_str(), error.c_str());
      reply = failure("failed", error);
    } else {
      if (!ready.missing.empty()) {  // the original bridge: it ran on the last values, and so do we
        ROS_WARN("bmtree: %s: %s did not arrive within input_wait (%ss): it runs with the last value received "
                 "on %s (a zero message if none), as the original library did",
                 callName(call).c_str(), inputsNamed(call, ready.missing).c_str(),
                 detail::seconds(input_wait_).c_str(), ready.missing.size() == 1 ? "its topic" : "their topics");
      }
      std::vector<std::size_t> occurrence;
      std::map<std::string, std::size_t> seen;
      for (const auto& t : call.topics) occurrence.push_back(seen[t]++);
      try {
        reply = ready.function.run(occurrence);
      } catch (const Rejected& e) {
        ROS_WARN("bmtree: %s rejected: %s", callName(call).c_str(), e.what());
        reply = failure("rejected", e.what());
      } catch (const Failure& e) {
        ROS_WARN("bmtree: %s failed: %s", callName(call).c_str(), e.what());
        reply = failure("failed", e.what());
      } catch (const std::exception& e) {
        const std::string type = detail::typeName(&typeid(e));
        ROS_ERROR("bmtree: %s threw %s: %s", callName(call).c_str(), type.c_str(), e.what());
        reply = failure("failed", type + ": " + e.what());
      } catch (...) {  // a vendor library may throw anything: the node must answer and live on
#if defined(__GNUG__)
        const std::string type = detail::typeName(abi::__cxa_current_exception_type());
#else
        const std::string type = "an unknown type";
#endif
        ROS_ERROR("bmtree: %s threw %s, which is not a std::exception", callName(call).c_str(), type.c_str());
        reply = failure("failed", type + ": an exception that is not a std::exception");
      }
    }
    if (stopRunning() && reply.value("status", "") != "cancelled") {
      reply["status"] = "cancelled";  // whatever it returned: the bridge throws it away
      reply["error"] = "cancelled while it ran";
    }
    if (!call.call_id.empty()) reply["call_id"] = call.call_id;  // a new bridge tells old answers apart
    std_msgs::String out;
    out.data = reply.dump();
    out_pub_.publish(out);
  }

  static nlohmann::json failure(const std::string& status, const std::string& error) {
    nlohmann::json j;
    j["outparam_names"] = nlohmann::json::array();
    j["outparam_topics"] = nlohmann::json::array();
    j["status"] = status;
    j["error"] = error;
    return j;
  }

  static constexpr std::size_t kMaxPayload = 1 << 20;
  static constexpr std::size_t kMaxEarlyCancels = 64;
  static constexpr std::size_t kMaxSubscribers = 64;
  ros::NodeHandle nh_;
  std::string module_;
  double input_wait_ = 1.0;
  ros::Publisher out_pub_;  // its connection callbacks run in the cancel thread
  ros::Publisher info_pub_;
  ros::Publisher event_pub_;
  ros::Subscriber in_sub_;
  // the spinner side (state_mutex_ guards what BM_input and the data topics change, and executing_)
  std::mutex state_mutex_;
  bool executing_ = false;
  std::map<std::string, std::unique_ptr<detail::ChannelBase>> channels_;
  std::map<std::string, std::string> types_;
  std::map<std::string, Function> functions_;
  std::deque<Pending> pending_;
  std::unique_ptr<detail::Waker> waker_;
  // the cancel thread's side (cancel_mutex_ guards running_, running_caller_, running_function_,
  // out_subscribers_, in_function_, hooks_, early_cancels_)
  ros::CallbackQueue cancel_queue_;
  ros::Subscriber cancel_sub_;
  std::unique_ptr<ros::AsyncSpinner> cancel_spinner_;
  mutable std::mutex cancel_mutex_;
  std::condition_variable cancel_cv_;
  std::atomic<bool> cancelled_{false};
  std::string running_;
  std::string running_caller_;    // the node that sent the running call (BM_input's callerid)
  std::string running_function_;
  std::map<std::string, int> out_subscribers_;  // node -> its connections to BM_output now
  bool in_function_ = false;
  std::uint64_t call_serial_ = 0;  // one more for each call that starts
  std::map<std::uint64_t, Hook> hooks_;
  std::uint64_t hook_counter_ = 0;
  std::deque<std::string> early_cancels_;
  detail::CallerWatch caller_watch_{[this](const std::string& node, const std::string& reason) { callerGone(node, reason); },
                                    [this](const std::string& node) { return callerWanted(node); }};
  detail::MasterWatch master_watch_;  // its thread ends before the rest goes
};

inline void CancelHook::reset() {
  if (owner_ != nullptr) owner_->removeHook(id_);
  owner_ = nullptr;
}

/// The node's name: `module`, or the new module name of a `_basic_mod:=NAME` argument, so that
/// two copies of one module renamed that way do not knock each other off the master (an
/// explicit `__name:=` still wins, in ros::init).
inline std::string nodeNameFor(int argc, char** argv, const std::string& module) {
  const std::string key = "_basic_mod:=";
  std::string name = module;
  for (int i = 1; i < argc; ++i) {
    std::string arg(argv[i]);
    if (arg.compare(0, key.size(), key) == 0 && arg.size() > key.size()) name = arg.substr(key.size());
  }
  // a node name is a ROS name: a letter, then letters, digits and '_' (else ros::init would throw)
  bool valid = !name.empty() && std::isalpha(static_cast<unsigned char>(name[0]));
  for (char c : name) valid = valid && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
  return valid ? name : module;
}

/// ros::init (the node is named `module`, as the original modules were, or after
/// `_basic_mod:=NAME`), construct the module, spin until shutdown. Returns the process exit code.
template <class Module>
int run(int argc, char** argv, const std::string& module) {
  ros::init(argc, argv, nodeNameFor(argc, argv, module));
  ros::NodeHandle nh;
  try {
    Module m(nh);
    ROS_INFO("bmtree: C++ basic module %s ready", m.moduleName().c_str());
    ros::spin();
  } catch (const std::logic_error& e) {
    ROS_FATAL("bmtree: %s", e.what());
    return 2;
  }
  return 0;
}

}  // namespace bmtree

#endif  // BMTREE_BASIC_MODULE_H

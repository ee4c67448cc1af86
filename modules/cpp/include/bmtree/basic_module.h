// bmtree C++ basic modules: a module is a class with one method per function.
//
// Speaks the original C++ basic-module protocol (manual section 4.3) to a bridge node
// (bmtree-bridge, or the original one): data topics /<BM>/<type> carry the values,
// /<BM>/BM_input and /<BM>/BM_output synchronise. Header-only, C++14, no sleeps, no
// rospack at run time. Functions run in the node's spinner thread, one at a time.
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
// What it does beyond the original utility: its inputs are only the data messages of the node
// that sent BM_input (connection header callerid: not its own outputs, not a third node's);
// the i-th such message received on a topic for a call is the i-th
// input listed on that topic, so two inputs of one type keep their values; a BM_input that
// overtook its inputs waits for them (bounded by ~input_wait, then the last values are used,
// as the original did); a function that throws bmtree::Failure / bmtree::Rejected (or any
// std::exception) answers BM_output with "error" and "status" keys, which bmtree-bridge
// reports and the original bridge ignores; an unknown function is answered with an error
// instead of silence; /<BM>/BM_info (latched) tells a bridge that this library is on the
// other side, so it needs no gap between the inputs and BM_input.
//
// Cancels: a bridge that gives up on a call (the tree halted it, or its --call-timeout passed)
// publishes {"call_id": ...} on /<BM>/BM_cancel. That topic is served by a thread of its own, so
// a cancel arrives while the function runs: a long function polls cancelled() or waits with
// sleepFor(seconds), stops the hardware and returns; its answer then says "cancelled" (the bridge
// throws its outputs away) and the module takes calls again at once. A call cancelled before it
// started is answered "cancelled" without running. The original bridge sends no cancels.
//
// A restarted ROS master is survived (master_watch.h): the module registers its topics again.
// stdout is line-buffered, so that prints reach a log file as they happen.
#ifndef BMTREE_BASIC_MODULE_H
#define BMTREE_BASIC_MODULE_H

#include <ros/ros.h>
#include <std_msgs/String.h>

#include <ros/callback_queue.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdio>
#include <deque>
#include <mutex>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

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

namespace detail {

/// A module's output mostly goes to a log file (roslaunch, systemd), where stdout is
/// block-buffered: prints (ROS_INFO too) would show up kilobytes late, or never after a kill.
/// Set before main(), so before any output.
inline bool lineBufferedStdout() { return std::setvbuf(stdout, nullptr, _IOLBF, 0) == 0; }
static const bool kStdoutLineBuffered = lineBufferedStdout();

/// One data topic: publisher, subscriber, and the messages received for the current call.
class ChannelBase {
 public:
  virtual ~ChannelBase() = default;
  /// Messages from `publisher` received since the last call took its inputs.
  virtual std::size_t fresh(const std::string& publisher) const = 0;
  /// Select `n` values from `publisher` for a call (its last `n` fresh ones, the last value
  /// received for any missing), and forget the fresh messages.
  virtual void select(std::size_t n, const std::string& publisher) = 0;
};

template <class M>
class Channel : public ChannelBase {
 public:
  Channel(ros::NodeHandle& nh, const std::string& topic, std::function<void()> on_data)
      : on_data_(std::move(on_data)) {
    pub_ = nh.advertise<M>(topic, 100);
    sub_ = nh.subscribe(topic, 100, &Channel::onMessage, this, ros::TransportHints().tcpNoDelay());
  }

  std::size_t fresh(const std::string& publisher) const override {
    std::size_t n = 0;
    for (const auto& f : fresh_) n += f.first == publisher ? 1 : 0;
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

  const M& selected(std::size_t i) const { return selected_.at(i); }

  void publish(const M& msg) const { pub_.publish(msg); }

 private:
  void onMessage(const ros::MessageEvent<M const>& event) {
    if (event.getPublisherName() == ros::this_node::getName()) return;  // our own output
    const M& msg = *event.getConstMessage();
    last_ = msg;
    if (fresh_.size() >= kMaxFresh) fresh_.pop_front();
    fresh_.emplace_back(event.getPublisherName(), msg);
    on_data_();
  }

  static constexpr std::size_t kMaxFresh = 64;
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

}  // namespace detail

/// Base class of a C++ basic module. Register functions with provide() in the constructor.
class BasicModule {
 public:
  BasicModule(ros::NodeHandle nh, const std::string& module) : nh_(nh) {
    ros::NodeHandle("~").param<std::string>("basic_mod", module_, module);
    ros::NodeHandle("~").param<double>("input_wait", input_wait_, 1.0);
    out_pub_ = nh_.advertise<std_msgs::String>("/" + module_ + "/BM_output", 10);
    info_pub_ = nh_.advertise<std_msgs::String>("/" + module_ + "/BM_info", 1, true);
    in_sub_ = nh_.subscribe("/" + module_ + "/BM_input", 10, &BasicModule::onInput, this,
                            ros::TransportHints().tcpNoDelay());
    wait_timer_ = nh_.createWallTimer(ros::WallDuration(input_wait_ > 0 ? input_wait_ : 0.001),
                                      &BasicModule::onInputWaitOver, this, true, false);
    // cancels must get through while a function blocks the node's spinner thread
    ros::NodeHandle cancel_nh(nh_);
    cancel_nh.setCallbackQueue(&cancel_queue_);
    cancel_sub_ = cancel_nh.subscribe("/" + module_ + "/BM_cancel", 10, &BasicModule::onCancel, this,
                                      ros::TransportHints().tcpNoDelay());
    cancel_spinner_.reset(new ros::AsyncSpinner(1, &cancel_queue_));
    cancel_spinner_->start();
    publishInfo();
    master_watch_.start();
  }
  virtual ~BasicModule() {
    cancel_spinner_->stop();
    cancel_sub_.shutdown();
  }
  BasicModule(const BasicModule&) = delete;
  BasicModule& operator=(const BasicModule&) = delete;

  const std::string& moduleName() const { return module_; }

 protected:
  /// True once the running call was cancelled, or the node is shutting down (Ctrl-C, rosnode
  /// kill: a respawned node must not drive the hardware beside this one): stop and return.
  bool cancelled() const { return cancelled_.load() || !ros::ok(); }

  /// Wait `seconds` unless the running call is cancelled (or the node shuts down) first; true if
  /// the whole time passed. Use it instead of sleeping, so that a halted tree stops the function
  /// at once.
  bool sleepFor(double seconds) {
    std::unique_lock<std::mutex> lock(cancel_mutex_);
    auto stop = [this]() { return cancelled(); };
    if (!(seconds > 0)) return !stop();  // also NaN: no wait
    using Clock = std::chrono::steady_clock;
    const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(std::min(seconds, 1e9)));
    while (Clock::now() < end) {  // a shutdown notifies nobody: look at it every 50 ms
      if (cancel_cv_.wait_until(lock, std::min(end, Clock::now() + std::chrono::milliseconds(50)), stop)) {
        return false;
      }
    }
    return !stop();
  }

  /// Register `fn` as the function `name`; its inputs are its parameters, in the definition's
  /// order; its outputs are the returned tuple's elements, named by `output_names`.
  template <class C, class... Out, class... In>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...),
               const std::array<std::string, sizeof...(Out)>& output_names) {
    C* self = static_cast<C*>(this);
    Function f;
    f.input_topics = {topicFor<In>()...};
    std::vector<std::string> output_topics = {topicFor<Out>()...};
    std::vector<std::string> names(output_names.begin(), output_names.end());
    f.output_names = names;
    f.output_topics = output_topics;
    for (const auto& n : names) {  // {"width"} for two outputs compiles: the missing name is ""
      if (n.empty()) {
        throw std::logic_error("provide(\"" + name + "\"): the function returns " + std::to_string(sizeof...(Out)) +
                               " outputs, so it needs " + std::to_string(sizeof...(Out)) +
                               " non-empty output names");
      }
    }
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
  struct Function {
    std::vector<std::string> input_topics;
    std::vector<std::string> output_names;
    std::vector<std::string> output_topics;
    std::function<nlohmann::json(const std::vector<std::size_t>&)> run;
  };
  struct Pending {
    std::string function;
    std::vector<std::string> topics;
    std::string bridge;   // the node that sent BM_input: only its data messages are inputs
    std::string call_id;  // sent by bmtree-bridge (not by the original): what a cancel names
  };

  template <class M>
  std::string topicFor() {
    std::string topic = dataTopic(module_, detail::datatypeOf<M>());
    auto it = channels_.find(topic);
    if (it == channels_.end()) {
      channels_[topic] = std::unique_ptr<detail::ChannelBase>(
          new detail::Channel<M>(nh_, topic, [this]() { onData(); }));
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
    info["protocol"] = 2;  // 2: takes cancels on /<BM>/BM_cancel
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
    } catch (const std::exception& e) {
      ROS_ERROR("bmtree: ignored a malformed BM_input message: %s", e.what());
      return;
    }
    pending_.push_back(std::move(p));
    runReady(false);
  }

  void onData() { runReady(false); }

  /// In the cancel thread: cancel the running call, or remember the id of one not started yet.
  void onCancel(const ros::MessageEvent<std_msgs::String const>& event) {
    std::string id;
    try {
      const std_msgs::String& msg = *event.getConstMessage();
      if (msg.data.size() > kMaxPayload) throw std::runtime_error("payload too large");
      id = nlohmann::json::parse(msg.data).at("call_id").get<std::string>();
    } catch (const std::exception& e) {
      ROS_ERROR("bmtree: ignored a malformed BM_cancel message: %s", e.what());
      return;
    }
    {
      std::lock_guard<std::mutex> lock(cancel_mutex_);
      if (!running_.empty() && id == running_) {
        cancelled_.store(true);
      } else {
        if (early_cancels_.size() >= kMaxEarlyCancels) early_cancels_.pop_front();
        early_cancels_.push_back(id);  // it may overtake its BM_input (another connection)
      }
    }
    cancel_cv_.notify_all();
  }

  /// Mark `call` running (cancels naming it now reach the function); true if it was cancelled
  /// before it started.
  bool startRunning(const Pending& call) {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    cancelled_.store(false);
    running_ = call.call_id;
    if (call.call_id.empty()) return false;
    auto it = std::find(early_cancels_.begin(), early_cancels_.end(), call.call_id);
    if (it == early_cancels_.end()) return false;
    early_cancels_.erase(it);
    return true;
  }

  /// The call has returned: true if it was cancelled meanwhile.
  bool stopRunning() {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    running_.clear();
    return cancelled_.exchange(false);
  }

  void onInputWaitOver(const ros::WallTimerEvent&) { runReady(true); }

  /// Run the oldest pending call once its inputs arrived (or, with `force`, the wait is over).
  void runReady(bool force) {
    while (!pending_.empty()) {
      const Pending& p = pending_.front();
      std::map<std::string, std::size_t> count;
      for (const auto& t : p.topics) ++count[t];
      bool complete = true;
      for (const auto& c : count) {
        auto it = channels_.find(c.first);
        if (it != channels_.end() && it->second->fresh(p.bridge) < c.second) complete = false;
      }
      if (!complete && !force) {
        if (!waiting_) {
          waiting_ = true;
          wait_timer_.stop();
          wait_timer_.start();
        }
        return;
      }
      waiting_ = false;
      wait_timer_.stop();
      force = false;
      Pending call = pending_.front();
      pending_.pop_front();
      execute(call, count);
    }
  }

  void execute(const Pending& call, const std::map<std::string, std::size_t>& count) {
    nlohmann::json reply;
    auto f = functions_.find(call.function);
    if (startRunning(call)) {
      for (const auto& c : count) {  // its inputs are spent all the same
        auto ch = channels_.find(c.first);
        if (ch != channels_.end()) ch->second->select(c.second, call.bridge);
      }
      reply = failure("cancelled", "cancelled before it started");
    } else if (f == functions_.end()) {
      reply = failure("rejected", "module " + module_ + " has no function " + call.function);
    } else if (call.topics != f->second.input_topics) {
      reply = failure("rejected", "function " + call.function + " takes its inputs on " +
                                      nlohmann::json(f->second.input_topics).dump() + ", not " +
                                      nlohmann::json(call.topics).dump());
    } else {
      for (const auto& c : count) channels_.at(c.first)->select(c.second, call.bridge);
      std::vector<std::size_t> occurrence;
      std::map<std::string, std::size_t> seen;
      for (const auto& t : call.topics) occurrence.push_back(seen[t]++);
      try {
        reply = f->second.run(occurrence);
      } catch (const Rejected& e) {
        reply = failure("rejected", e.what());
      } catch (const Failure& e) {
        reply = failure("failed", e.what());
      } catch (const std::exception& e) {
        reply = failure("failed", std::string("exception: ") + e.what());
      } catch (...) {  // a vendor library may throw anything: the node must answer and live on
        reply = failure("failed", "exception: an exception that is not a std::exception");
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
  ros::NodeHandle nh_;
  std::string module_;
  double input_wait_ = 1.0;
  ros::Publisher out_pub_;
  ros::Publisher info_pub_;
  ros::Subscriber in_sub_;
  ros::WallTimer wait_timer_;
  bool waiting_ = false;
  std::map<std::string, std::unique_ptr<detail::ChannelBase>> channels_;
  std::map<std::string, std::string> types_;
  std::map<std::string, Function> functions_;
  std::deque<Pending> pending_;
  // the cancel thread's side (cancel_mutex_ guards running_ and early_cancels_)
  ros::CallbackQueue cancel_queue_;
  ros::Subscriber cancel_sub_;
  std::unique_ptr<ros::AsyncSpinner> cancel_spinner_;
  std::mutex cancel_mutex_;
  std::condition_variable cancel_cv_;
  std::atomic<bool> cancelled_{false};
  std::string running_;
  std::deque<std::string> early_cancels_;
  detail::MasterWatch master_watch_;  // its thread ends before the rest goes
};

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

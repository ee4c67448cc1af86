// bmtree C++ basic modules: the class bmtree::BasicModule. Its public API, its templates and its
// members are here; its other member functions are defined (inline) in basic_module_calls.h (its
// topics, BM_input, running a call and answering it, BM_info, events) and basic_module_cancels.h
// (cancels, onCancel() callbacks, callers that are gone), which this header includes at its end.
// Part of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_BASIC_MODULE_CLASS_H
#define BMTREE_BASIC_MODULE_CLASS_H

#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_msgs/String.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "caller_watch.h"
#include "cancel_hook.h"
#include "detail/channel.h"
#include "detail/waker.h"
#include "event_param.h"
#include "master_watch.h"

namespace bmtree {

/// Base class of a C++ basic module. Register functions with provide() in the constructor.
class BasicModule {
 public:
  using Clock = std::chrono::steady_clock;

  inline BasicModule(ros::NodeHandle nh, const std::string& module);
  inline virtual ~BasicModule();
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
  inline bool emit(const std::string& event, const std::vector<EventParam>& params) const;

  /// True once the running call was cancelled, or the node is shutting down (Ctrl-C, rosnode
  /// kill: a respawned node must not drive the hardware beside this one): stop and return.
  /// Thread-safe: a helper object of the function may poll it from any thread.
  bool cancelled() const { return cancelled_.load() || !ros::ok(); }

  /// Wait `seconds` unless the running call is cancelled (or the node shuts down) first; true if
  /// the whole time passed. Use it instead of sleeping, so that a halted tree stops the function
  /// at once.
  inline bool sleepFor(double seconds);

  /// The call_id of the running call ("" outside a function, and for calls of the original
  /// bridge, which sends none).
  inline std::string callId() const;

  /// Inside a function: call `fn` once when the running call is cancelled, in the library's cancel
  /// thread (the one that receives BM_cancel), while the function itself goes on running in its own
  /// thread: make what `fn` touches safe to use from two threads (an atomic, a mutex, a driver's
  /// thread-safe stop), and return promptly (the call's answer waits for it). If the call is
  /// cancelled already, `fn` runs at once, in the calling thread. A call cancelled while `fn` is
  /// registered always gets it called, once: should the function see the cancel (sleepFor(),
  /// cancelled()) and drop the CancelHook before the cancel thread came to `fn`, the CancelHook's
  /// destructor calls it, in the function's thread. Not called for a call that ends uncancelled,
  /// nor on shutdown (poll cancelled() for that). Keep the returned CancelHook while `fn` may run:
  ///   bmtree::CancelHook hook = onCancel([this]() { driver_.halt(); });
  /// Outside a function it throws std::logic_error.
#if defined(__GNUG__)
  __attribute__((warn_unused_result))
#endif
  inline CancelHook onCancel(std::function<void()> fn);

 protected:
  /// Register `fn` as the function `name`; its inputs are its parameters, in the definition's
  /// order; its outputs are the returned tuple's elements, named by `output_names`.
  template <class C, class... Out, class... In>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...),
               const std::array<std::string, sizeof...(Out)>& output_names) {
    C* self = static_cast<C*>(this);
    add(name, std::vector<std::string>(output_names.begin(), output_names.end()), Types<Out...>(), Types<In...>(),
        [self, fn](const In&... in) { return (self->*fn)(in...); });
  }

  /// The same for a `const` method (a getter such as `status() const`).
  template <class C, class... Out, class... In>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...) const,
               const std::array<std::string, sizeof...(Out)>& output_names) {
    const C* self = static_cast<const C*>(this);
    add(name, std::vector<std::string>(output_names.begin(), output_names.end()), Types<Out...>(), Types<In...>(),
        [self, fn](const In&... in) { return (self->*fn)(in...); });
  }

  /// The names written as a list of texts, `{"final_pos", "distance"}` (what overload resolution picks
  /// for them): a name too few or too many is a compile error, not an error when the node starts.
  template <class C, class... Out, class... In, std::size_t K>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...),
               const char* const (&output_names)[K]) {
    static_assert(K == sizeof...(Out), "bmtree provide(): give one output name per element of the std::tuple "
                                       "the function returns");
    C* self = static_cast<C*>(this);
    add(name, std::vector<std::string>(output_names, output_names + K), Types<Out...>(), Types<In...>(),
        [self, fn](const In&... in) { return (self->*fn)(in...); });
  }

  template <class C, class... Out, class... In, std::size_t K>
  void provide(const std::string& name, std::tuple<Out...> (C::*fn)(const In&...) const,
               const char* const (&output_names)[K]) {
    static_assert(K == sizeof...(Out), "bmtree provide(): give one output name per element of the std::tuple "
                                       "the function returns");
    const C* self = static_cast<const C*>(this);
    add(name, std::vector<std::string>(output_names, output_names + K), Types<Out...>(), Types<In...>(),
        [self, fn](const In&... in) { return (self->*fn)(in...); });
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
    bool due = false;      // the call was cancelled while it was registered: it runs, once, whatever comes next
    bool fired = false;    // a thread has taken it to run (the cancel thread, or the one that unregisters it)
    bool running = false;
    std::thread::id thread;
  };
  /// What runReady() hands to execute(): a call whose inputs are selected.
  struct Ready {
    Pending call;
    bool known = false;
    Function function;
    std::vector<std::size_t> missing;  // positions of the inputs that did not arrive in time
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

  template <class... T>
  struct Types {};

  template <class... Out, class... In, class Fn>
  void add(const std::string& name, const std::vector<std::string>& names, Types<Out...>, Types<In...>, Fn fn) {
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
    f.run = [this, fn, names, output_topics](const std::vector<std::size_t>& occurrence) {
      std::tuple<Out...> out = invoke<In...>(fn, occurrence, std::index_sequence_for<In...>());
      publishAll(out, std::index_sequence_for<Out...>());
      nlohmann::json reply;
      reply["outparam_names"] = names;
      reply["outparam_topics"] = output_topics;
      return reply;
    };
    functions_[name] = std::move(f);
    publishInfo();
  }

  template <class... In, class Fn, std::size_t... I>
  auto invoke(const Fn& fn, const std::vector<std::size_t>& occurrence, std::index_sequence<I...>)
      -> decltype(fn(std::declval<const In&>()...)) {
    (void)occurrence;  // unused when the function has no inputs
    return fn(channel<In>().selected(occurrence[I])...);
  }

  template <class... Out, std::size_t... I>
  void publishAll(const std::tuple<Out...>& out, std::index_sequence<I...>) {
    int expand[] = {0, (channel<Out>().publish(std::get<I>(out)), 0)...};
    (void)expand;
  }

  // the spinner side: basic_module_calls.h
  inline void publishInfo();
  inline void onInput(const ros::MessageEvent<std_msgs::String const>& event);
  inline void runReady();
  static inline std::string inputsNamed(const Pending& call, const std::vector<std::size_t>& positions);
  static inline std::string callName(const Pending& call);
  inline void execute(const Ready& ready);
  static inline nlohmann::json failure(const std::string& status, const std::string& error);

  // the cancel thread's side, and the caller watch's: basic_module_cancels.h
  inline void onCancelMessage(const ros::MessageEvent<std_msgs::String const>& event);
  inline bool cancelNow();
  inline void runHooks(std::uint64_t serial);
  inline bool runDueHook(std::unique_lock<std::mutex>& lock, std::uint64_t id);
  inline void callHook(const std::function<void()>& fn);
  inline void removeHook(std::uint64_t id);
  inline bool startRunning(const Pending& call);
  inline bool stopRunning();
  inline void onOutputConnect(const ros::SingleSubscriberPublisher& link);
  inline void onOutputDisconnect(const ros::SingleSubscriberPublisher& link);
  inline bool callerWanted(const std::string& node);
  inline void callerGone(const std::string& node, const std::string& reason);
  inline void cancelCallOf(const std::string& node, const std::string& reason);

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

}  // namespace bmtree

// the definitions of the member functions declared above
#include "basic_module_calls.h"
#include "basic_module_cancels.h"

#endif  // BMTREE_BASIC_MODULE_CLASS_H

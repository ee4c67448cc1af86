// bmtree C++ basic modules: how BasicModule runs a call (its definitions, inline, beside the class
// in basic_module_class.h): the module's topics (constructor), BM_input, the wait for its inputs,
// running the function and answering on BM_output; BM_info and events. Part of
// <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_BASIC_MODULE_CALLS_H
#define BMTREE_BASIC_MODULE_CALLS_H

#include <ros/ros.h>
#include <std_msgs/String.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <exception>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <typeinfo>
#include <utility>
#include <vector>

#if defined(__GNUG__)
#include <cxxabi.h>
#endif

#include <nlohmann/json.hpp>

#include "api.h"
#include "basic_module_class.h"
#include "detail/text.h"
#include "detail/waker.h"
#include "errors.h"
#include "event_param.h"

namespace bmtree {
namespace detail {

/// The JSON text of `j`. A string of it that is not UTF-8 (a Latin-1 message of a vendor's driver
/// in an exception's what()) has those bytes replaced by U+FFFD: nlohmann's dump() would throw
/// out of the callback and end the node.
inline std::string jsonText(const nlohmann::json& j) {
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

/// The error of a call whose function threw bmtree::Failure or bmtree::Rejected (`type`): its text,
/// or, for an empty one (which a bridge would take for no error at all), that it gave none.
inline std::string thrownText(const char* what, const char* type) {
  if (what != nullptr && *what != '\0') return what;
  return std::string("the C++ function gave no message (it threw bmtree::") + type + "(\"\"))";
}

}  // namespace detail
}  // namespace bmtree

namespace bmtree {

/// Reads its private parameters, makes its topics (the cancel side's on the cancel thread's queue),
/// starts its threads and publishes BM_info.
inline BasicModule::BasicModule(ros::NodeHandle nh, const std::string& module) : nh_(nh) {
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

inline BasicModule::~BasicModule() {
  caller_watch_.stop();
  cancel_spinner_->stop();
  out_pub_.shutdown();  // its connection callbacks go to cancel_queue_, which goes before it
  cancel_sub_.shutdown();
  in_sub_.shutdown();
  waker_.reset();
}

// emit(): documented in the class (basic_module_class.h)
inline bool BasicModule::emit(const std::string& event, const std::vector<EventParam>& params) const {
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
  msg.data = detail::jsonText(j);
  if (msg.data.size() > kMaxPayload) {
    ROS_ERROR("bmtree: emit(\"%s\"): the event is %zu bytes, over the %zu the bridge takes; nothing sent",
              event.c_str(), msg.data.size(), kMaxPayload);
    return false;
  }
  event_pub_.publish(msg);
  return true;
}


inline void BasicModule::publishInfo() {
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
  msg.data = detail::jsonText(info);
  info_pub_.publish(msg);
}

inline void BasicModule::onInput(const ros::MessageEvent<std_msgs::String const>& event) {
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

/// Run the pending calls in order, each once its inputs arrived or its wait for them is over.
/// Any thread (the spinner's, also re-entered through a ros::spinOnce() inside a function, or
/// several of a multi-threaded spinner): while one function runs, the others only queue.
inline void BasicModule::runReady() {
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
inline std::string BasicModule::inputsNamed(const Pending& call, const std::vector<std::size_t>& positions) {
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

inline std::string BasicModule::callName(const Pending& call) {
  return call.function + (call.call_id.empty() ? std::string(" (no call id)") : " (call " + call.call_id + ")");
}

inline void BasicModule::execute(const Ready& ready) {
  const Pending& call = ready.call;
  nlohmann::json reply;
  if (startRunning(call)) {
    reply = failure("cancelled", "cancelled before it started");
  } else if (!ready.known) {
    reply = failure("rejected", "module " + module_ + " has no function " + call.function);
  } else if (call.topics != ready.function.input_topics) {
    reply = failure("rejected", "function " + call.function + " takes its inputs on " +
                                    detail::jsonText(ready.function.input_topics) + ", not " +
                                    detail::jsonText(call.topics));
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
      const std::string error = detail::thrownText(e.what(), "Rejected");
      ROS_WARN("bmtree: %s rejected: %s", callName(call).c_str(), error.c_str());
      reply = failure("rejected", error);
    } catch (const Failure& e) {
      const std::string error = detail::thrownText(e.what(), "Failure");
      ROS_WARN("bmtree: %s failed: %s", callName(call).c_str(), error.c_str());
      reply = failure("failed", error);
    } catch (const std::exception& e) {
      const std::string type = detail::typeName(&typeid(e));
      ROS_ERROR("bmtree: %s threw %s: %s", callName(call).c_str(), type.c_str(), e.what());
      reply = failure("failed", *e.what() ? type + ": " + e.what() : type + ", with no message");
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
  out.data = detail::jsonText(reply);
  out_pub_.publish(out);
}

inline nlohmann::json BasicModule::failure(const std::string& status, const std::string& error) {
  nlohmann::json j;
  j["outparam_names"] = nlohmann::json::array();
  j["outparam_topics"] = nlohmann::json::array();
  j["status"] = status;
  j["error"] = error;
  return j;
}

}  // namespace bmtree

#endif  // BMTREE_BASIC_MODULE_CALLS_H

// bmtree C++ basic modules: the caller watch, whether the node that sent the running call (a
// bridge) is still there, once its connection to the module's BM_output drops: a caller whose
// process is gone cannot take the answer, so the module cancels the call (basic_module_cancels.h).
// It asks as the master watch does (master_watch.h), over detail/rpc_line.h. Part of
// <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_CALLER_WATCH_H
#define BMTREE_CALLER_WATCH_H

#include <ros/ros.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

#include "detail/rpc_line.h"

namespace bmtree {
namespace detail {

/// Whether the nodes that call the module (its bridges) are still there: a caller's connection to
/// BM_output that drops while its call runs is a process that died (roscpp drops a subscriber's
/// connection as soon as its socket closes), a node that unsubscribed, or, rarely, a network fault.
/// The watch tells them apart by the caller's XML-RPC port: refused (or its pid changed: another
/// process of that name) is gone; a node that answers with the pid it had when it connected lives
/// (rospy connects again by itself). Each caller's URI and pid are learnt when it connects (one
/// master lookup and one getPid per connection, not per call), so a caller that dies while the master
/// is away is still recognised. Every question is bounded (`timeout`, 0.5 s) and asked from the
/// watch's own thread; a caller that lives (a node that stops cleanly leaves its connections before
/// its process ends), or that cannot be told (the master does not answer, the caller does not answer
/// in time: a slow node is not a dead one), is asked again every `period` while `wanted(node)` says
/// that a call of that node still runs unconnected.
class CallerWatch {
 public:
  using Gone = std::function<void(const std::string& node, const std::string& reason)>;
  using Wanted = std::function<bool(const std::string& node)>;

  CallerWatch(Gone gone, Wanted wanted, double period = 0.5, double timeout = 0.5)
      : gone_(std::move(gone)), wanted_(std::move(wanted)), period_(period), timeout_(timeout) {}
  ~CallerWatch() { stop(); }
  CallerWatch(const CallerWatch&) = delete;
  CallerWatch& operator=(const CallerWatch&) = delete;

  /// After ros::init.
  void start() {
    if (thread_.joinable()) return;
    if (::pipe2(wake_, O_NONBLOCK | O_CLOEXEC) != 0) {
      ROS_ERROR("bmtree: no caller watch (pipe: %s): a call whose caller died runs to its end", strerror(errno));
      return;
    }
    me_ = ros::this_node::getName();
    master_host_ = ros::master::getHost();
    master_port_ = static_cast<int>(ros::master::getPort());
    thread_ = std::thread(&CallerWatch::loop, this);
    std::lock_guard<std::mutex> lock(mutex_);
    started_ = true;
  }

  /// End the thread at once, whatever it waits for.
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      quit_ = true;
    }
    cv_.notify_all();
    if (wake_[1] >= 0) {
      char x = 'x';
      (void)!::write(wake_[1], &x, 1);
    }
    if (thread_.joinable()) thread_.join();
    for (int& fd : wake_) {
      if (fd >= 0) ::close(fd);
      fd = -1;
    }
  }

  /// `node` connected to BM_output: learn its URI and pid (any thread; returns at once).
  void learn(const std::string& node) { post(node, false); }

  /// `node`, which a running call came from, has no connection to BM_output any more: is it gone?
  void check(const std::string& node) { post(node, true); }

 private:
  enum Verdict { kAlive, kGone, kUnknown };
  struct Task {
    std::string node;
    bool check;
    WatchClock::time_point when;
  };
  struct Known {
    std::string uri;
    long pid;
  };

  void post(const std::string& node, bool check, double delay = 0.0) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (quit_ || !started_ || tasks_.size() >= kMaxTasks) return;
      if (check && std::any_of(tasks_.begin(), tasks_.end(), [&](const Task& t) { return t.check && t.node == node; })) {
        return;  // asked already
      }
      tasks_.push_back(Task{node, check, after(delay)});
    }
    cv_.notify_all();
  }

  void loop() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!quit_) {
      auto due = std::find_if(tasks_.begin(), tasks_.end(), [](const Task& t) { return t.when <= WatchClock::now(); });
      if (due == tasks_.end()) {
        if (tasks_.empty()) {
          cv_.wait(lock);
        } else {
          auto next = std::min_element(tasks_.begin(), tasks_.end(),
                                       [](const Task& a, const Task& b) { return a.when < b.when; });
          cv_.wait_until(lock, next->when);
        }
        continue;
      }
      Task task = *due;
      tasks_.erase(due);
      lock.unlock();
      run(task);
      lock.lock();
    }
  }

  void run(const Task& task) {
    if (!ros::ok()) return;
    if (!task.check) {  // a connection: remember which process it is (not the one before it of that name)
      known_.erase(task.node);
      Known k;
      if (lookup(task.node, k.uri) == kAlive && pidAt(k.uri, k.pid) == kAlive) remember(task.node, k);
      return;
    }
    if (!wanted_(task.node)) return;  // its call has ended, or it is connected again
    std::string reason;
    Verdict v = verdict(task.node, reason);
    if (v == kGone) {
      known_.erase(task.node);
      gone_(task.node, reason);
    } else {  // asked again while its call runs unconnected: a node that stops (Ctrl-C) leaves its
      post(task.node, true, period_);  // connections before its process ends; one that lives connects again
    }
  }

  /// Is the process that connected as `node` still there? `reason` says why not.
  Verdict verdict(const std::string& node, std::string& reason) {
    auto it = known_.find(node);
    if (it != known_.end()) {
      const Known k = it->second;
      long pid = -1;
      Verdict v = pidAt(k.uri, pid);
      if (v == kGone) {
        reason = "its process is gone: nothing answers at " + k.uri;
      } else if (v == kAlive && pid != k.pid) {
        reason = "another process of that name runs now (pid " + std::to_string(pid) + ", was " +
                 std::to_string(k.pid) + "): it cannot know the call";
        v = kGone;
      }
      return v;
    }
    std::string uri;
    Verdict v = lookup(node, uri);
    if (v == kGone) {
      reason = "it is no longer registered with the ROS master";
      return v;
    }
    if (v != kAlive) return v;
    long pid = -1;
    v = pidAt(uri, pid);
    if (v == kGone) reason = "its process is gone: nothing answers at " + uri;
    return v;
  }

  /// The node's XML-RPC URI from the master: kGone if the master does not know it.
  Verdict lookup(const std::string& node, std::string& uri) {
    RpcLine master(master_host_, master_port_, wake_[0]);
    XmlRpc::XmlRpcValue answer;
    if (master.call("lookupNode", rpcParams({me_, node}), answer, 2 * timeout_) != RpcLine::kOk || !isArray(answer) ||
        answer.size() != 3 || answer[0].getType() != XmlRpc::XmlRpcValue::TypeInt) {
      return kUnknown;
    }
    if (static_cast<int>(answer[0]) != 1 || !isString(answer[2])) return kGone;  // "unknown node"
    uri = str(answer[2]);
    return kAlive;
  }

  /// The pid of the node at `uri`: kGone if its port refuses (or the connection breaks).
  Verdict pidAt(const std::string& uri, long& pid) {
    std::string host;
    int port = 0;
    if (!split(uri, host, port)) return kUnknown;
    RpcLine line(host, port, wake_[0]);
    XmlRpc::XmlRpcValue answer, value;
    RpcLine::Result r = line.call("getPid", rpcParams({me_}), answer, timeout_);
    if (r == RpcLine::kBroken) return kGone;
    if (r != RpcLine::kOk || !rosValue(answer, value) || value.getType() != XmlRpc::XmlRpcValue::TypeInt) {
      return kUnknown;
    }
    pid = static_cast<int>(value);
    return kAlive;
  }

  /// "http://host:port/" -> host, port ("[::1]" -> "::1").
  static bool split(const std::string& uri, std::string& host, int& port) {
    std::size_t start = uri.find("://");
    start = start == std::string::npos ? 0 : start + 3;
    std::size_t end = uri.find('/', start);
    std::string hostport = uri.substr(start, end == std::string::npos ? std::string::npos : end - start);
    std::size_t colon = hostport.rfind(':');
    if (colon == std::string::npos || colon + 1 >= hostport.size()) return false;
    host = hostport.substr(0, colon);
    if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
    char* rest = nullptr;
    long p = std::strtol(hostport.c_str() + colon + 1, &rest, 10);
    if (rest == nullptr || *rest != '\0' || p <= 0 || p > 65535 || host.empty()) return false;
    port = static_cast<int>(p);
    return true;
  }

  void remember(const std::string& node, const Known& k) {
    if (known_.size() >= kMaxKnown && known_.find(node) == known_.end()) known_.erase(known_.begin());
    known_[node] = k;
  }

  static constexpr std::size_t kMaxTasks = 256;
  static constexpr std::size_t kMaxKnown = 64;
  const Gone gone_;
  const Wanted wanted_;
  const double period_, timeout_;
  std::string me_;
  std::string master_host_;
  int master_port_ = 0;
  std::mutex mutex_;  // guards tasks_, started_ and quit_; known_ is the thread's own
  std::condition_variable cv_;
  std::deque<Task> tasks_;
  bool started_ = false;
  bool quit_ = false;
  std::map<std::string, Known> known_;
  int wake_[2] = {-1, -1};  // stop() writes to [1]; every question also watches [0]
  std::thread thread_;
};

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_CALLER_WATCH_H

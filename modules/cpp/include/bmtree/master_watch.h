// bmtree C++ basic modules: survive a restarted ROS master (the C++ side of comm/masterwatch.py).
//
// roscpp registers a node's topics once, when they are made; a master that is killed and started
// again knows nothing, so nodes started afterwards (a new bmtree-bridge, `bmtree modules --live`)
// never find the module. Connections between running nodes are plain TCP and survive the master,
// so registering again is enough to be whole again.
//
// MasterWatch asks the master for its pid over one kept-alive HTTP connection, then waits, without
// polling, for the master to close it: a master that dies closes it at once, and TCP keepalive
// probes notice a master machine that went away. While the master does not answer (or does not
// keep connections open) it asks every `period` seconds. When the master answers again after
// being unreachable, or with another pid, it registers every publication, subscription and service
// of this node again with the node's own XML-RPC URI, and hands each subscription the publishers
// the master knows plus the ones it is connected to (roscpp drops a connection to a publisher
// missing from an update, and a running bridge may not have registered again yet).
//
// Its own small XML-RPC client, not roscpp's: roscpp's waits without a time limit (a master
// machine that vanished would hold the thread, and the node's exit, for minutes), and every wait
// here is also cut short by stop(). The library sets no parameters, so there are none to set again.
// What it cannot get back: parameters set by others (launch files, `rosparam`, private
// `_name:=value` arguments: the node keeps the values it read at start), services advertised after
// the module was made, and messages published while nobody was connected.
//
// CallerWatch, below, asks the same way whether the node that sent the running call (a bridge) is
// still there, once its connection to the module's BM_output drops: a caller whose process is gone
// cannot take the answer, so the module cancels the call (basic_module.h).
#ifndef BMTREE_MASTER_WATCH_H
#define BMTREE_MASTER_WATCH_H

#include <ros/ros.h>
#include <ros/connection_manager.h>
#include <ros/network.h>
#include <ros/service_manager.h>
#include <ros/xmlrpc_manager.h>
#include <xmlrpcpp/XmlRpcException.h>
#include <xmlrpcpp/XmlRpcUtil.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace bmtree {
namespace detail {

using WatchClock = std::chrono::steady_clock;

inline WatchClock::time_point after(double seconds) {
  return WatchClock::now() + std::chrono::duration_cast<WatchClock::duration>(std::chrono::duration<double>(seconds));
}

/// Wait until `fd` has `events` (or an error), `wake` is readable or `deadline` passes: 1 ready,
/// 0 timed out, -1 woken. `fd` < 0 waits on `wake` alone.
inline int waitReady(int fd, short events, int wake, WatchClock::time_point deadline) {
  for (;;) {
    auto us = std::chrono::duration_cast<std::chrono::microseconds>(deadline - WatchClock::now()).count();
    long long ms = std::max<long long>(0, std::min<long long>((us + 999) / 1000, 1 << 30));  // not 0 before the end
    pollfd fds[2] = {{wake, POLLIN, 0}, {fd, events, 0}};
    int n = ::poll(fds, fd >= 0 ? 2 : 1, static_cast<int>(ms));
    if (n < 0 && errno == EINTR) continue;  // roscpp's SIGINT handler
    if (n < 0 || fds[0].revents != 0) return -1;
    if (n > 0) return 1;
    if (WatchClock::now() >= deadline) return 0;
  }
}

/// One HTTP connection to an XML-RPC server (the master, or this node's own), kept open when the
/// server keeps it; every wait is bounded and cut short by the watch's wake pipe.
class RpcLine {
 public:
  enum Result { kOk, kBroken, kTimeout, kStopped };

  RpcLine(std::string host, int port, int wake) : host_(std::move(host)), port_(port), wake_(wake) {}
  ~RpcLine() { close(); }
  RpcLine(const RpcLine&) = delete;
  RpcLine& operator=(const RpcLine&) = delete;

  /// The kept connection (-1 when none): readable once the server closed it.
  int fd() const { return fd_; }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

  /// Call `method` with the array `params`; kOk with the answer's value in `result`.
  Result call(const std::string& method, const XmlRpc::XmlRpcValue& params, XmlRpc::XmlRpcValue& result,
              double timeout) {
    std::string body = "<?xml version=\"1.0\"?>\r\n<methodCall><methodName>" + method + "</methodName>\r\n<params>";
    for (int i = 0; i < params.size(); ++i) body += "<param>" + params[i].toXml() + "</param>";
    body += "</params></methodCall>\r\n";
    const std::string request = "POST / HTTP/1.1\r\nHost: " + host_ + ":" + std::to_string(port_) +
                                "\r\nUser-Agent: bmtree\r\nContent-Type: text/xml\r\nContent-Length: " +
                                std::to_string(body.size()) + "\r\n\r\n" + body;
    const auto deadline = after(timeout);
    for (bool fresh : {fd_ < 0, true}) {  // a kept connection closed meanwhile: once more, afresh
      if (fd_ < 0) {
        Result r = open(deadline);
        if (r != kOk) return r;
      }
      std::string answer;
      Result r = exchange(request, answer, deadline);
      if (r == kOk) return parse(answer, result) ? kOk : kBroken;
      close();
      if (r != kBroken || fresh) return r;
    }
    return kBroken;
  }

 private:
  Result open(WatchClock::time_point deadline) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    if (::getaddrinfo(host_.c_str(), std::to_string(port_).c_str(), &hints, &found) != 0) return kBroken;
    Result r = kBroken;
    for (addrinfo* a = found; a != nullptr && r == kBroken; a = a->ai_next) {
      int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
      if (fd < 0) continue;
      if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
        r = kOk;
      } else if (errno == EINPROGRESS) {
        int w = waitReady(fd, POLLOUT, wake_, deadline);
        r = w > 0 ? kBroken : w == 0 ? kTimeout : kStopped;
        int err = 0;
        socklen_t len = sizeof(err);
        if (w > 0 && ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0) r = kOk;
      }
      if (r == kOk) {
        fd_ = fd;
        keepalive(fd);
      } else {
        ::close(fd);
      }
    }
    ::freeaddrinfo(found);
    return r;
  }

  /// Let the kernel probe an idle connection, so that a vanished master machine is noticed (~11 s).
  static void keepalive(int fd) {
    int on = 1, idle = 5, interval = 2, count = 3;
    ::setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &on, sizeof(on));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPIDLE, &idle, sizeof(idle));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPINTVL, &interval, sizeof(interval));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPCNT, &count, sizeof(count));
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
  }

  /// Send `request`, read the answer's body; the connection stays open if the server keeps it.
  Result exchange(const std::string& request, std::string& body, WatchClock::time_point deadline) {
    for (std::size_t sent = 0; sent < request.size();) {
      ssize_t n = ::send(fd_, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);  // no SIGPIPE
      if (n > 0) {
        sent += static_cast<std::size_t>(n);
      } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
        int w = waitReady(fd_, POLLOUT, wake_, deadline);
        if (w <= 0) return w == 0 ? kTimeout : kStopped;
      } else {
        return kBroken;
      }
    }
    std::string in;
    std::size_t header_end = std::string::npos, length = 0;
    bool has_length = false, keep = false;
    for (;;) {
      if (header_end == std::string::npos) {
        header_end = in.find("\r\n\r\n");
        if (header_end == std::string::npos && in.size() > kMaxHeader) return kBroken;
        if (header_end != std::string::npos && !readHeader(in.substr(0, header_end), has_length, length, keep)) {
          return kBroken;
        }
      }
      if (header_end != std::string::npos && has_length && in.size() - header_end - 4 >= length) break;
      char buf[16384];
      ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n > 0) {
        in.append(buf, static_cast<std::size_t>(n));
        if (in.size() > kMaxBody) return kBroken;
      } else if (n == 0) {  // closed: the end of an answer without a length, or a broken one
        if (header_end == std::string::npos || has_length) return kBroken;
        keep = false;
        break;
      } else if (errno == EAGAIN || errno == EINTR) {
        int w = waitReady(fd_, POLLIN, wake_, deadline);
        if (w <= 0) return w == 0 ? kTimeout : kStopped;
      } else {
        return kBroken;
      }
    }
    body = in.substr(header_end + 4, has_length ? length : std::string::npos);
    if (!keep) close();
    return kOk;
  }

  static bool readHeader(std::string header, bool& has_length, std::size_t& length, bool& keep) {
    for (char& c : header) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (header.compare(0, 9, "http/1.1 ") != 0 && header.compare(0, 9, "http/1.0 ") != 0) return false;
    if (header.compare(9, 3, "200") != 0) return false;
    keep = header[7] == '1';  // HTTP/1.1 keeps the connection unless it says otherwise
    std::size_t at = header.find("\r\ncontent-length:");
    if (at != std::string::npos) {
      has_length = true;
      length = std::strtoul(header.c_str() + at + 17, nullptr, 10);
    }
    if (header.find("\r\nconnection: close") != std::string::npos) keep = false;
    if (header.find("\r\nconnection: keep-alive") != std::string::npos) keep = true;
    keep = keep && has_length;
    return true;
  }

  static bool parse(const std::string& answer, XmlRpc::XmlRpcValue& result) {
    int offset = 0;
    try {  // <methodResponse><params><param><value>; a <fault> is no answer
      return XmlRpc::XmlRpcUtil::findTag("<methodResponse>", answer, &offset) &&
             XmlRpc::XmlRpcUtil::nextTagIs("<params>", answer, &offset) &&
             XmlRpc::XmlRpcUtil::nextTagIs("<param>", answer, &offset) && result.fromXml(answer, &offset);
    } catch (const XmlRpc::XmlRpcException&) {
      return false;
    }
  }

  static constexpr std::size_t kMaxHeader = 1 << 16;
  static constexpr std::size_t kMaxBody = 1 << 26;  // getSystemState of a large graph
  std::string host_;
  int port_;
  int wake_;
  int fd_ = -1;
};

/// The value of a ROS API answer [code, message, value] when its code is 1.
inline bool rosValue(const XmlRpc::XmlRpcValue& answer, XmlRpc::XmlRpcValue& value) {
  if (answer.getType() != XmlRpc::XmlRpcValue::TypeArray || answer.size() != 3) return false;
  const XmlRpc::XmlRpcValue& code = answer[0];
  if (code.getType() != XmlRpc::XmlRpcValue::TypeInt || static_cast<const int&>(code) != 1) return false;
  value = answer[2];
  return true;
}

inline XmlRpc::XmlRpcValue rpcParams(std::initializer_list<XmlRpc::XmlRpcValue> values) {
  XmlRpc::XmlRpcValue params;
  params.setSize(static_cast<int>(values.size()));
  int i = 0;
  for (const auto& v : values) params[i++] = v;
  return params;
}

inline bool isArray(const XmlRpc::XmlRpcValue& v) { return v.getType() == XmlRpc::XmlRpcValue::TypeArray; }
inline bool isString(const XmlRpc::XmlRpcValue& v) { return v.getType() == XmlRpc::XmlRpcValue::TypeString; }
inline std::string str(const XmlRpc::XmlRpcValue& v) { return static_cast<const std::string&>(v); }

/// The module's master watch: start() after ros::init (BasicModule does), stop() or destroy it
/// to end its thread.
class MasterWatch {
 public:
  explicit MasterWatch(double period = 0.5, double timeout = 2.0, double recheck = 60.0)
      : period_(period), timeout_(timeout), recheck_(recheck) {}
  ~MasterWatch() { stop(); }
  MasterWatch(const MasterWatch&) = delete;
  MasterWatch& operator=(const MasterWatch&) = delete;

  void start() {
    if (thread_.joinable()) return;
    if (::pipe2(wake_, O_NONBLOCK | O_CLOEXEC) != 0) {
      ROS_ERROR("bmtree: no master watch (pipe: %s): a restarted ROS master will not know this node", strerror(errno));
      return;
    }
    master_uri_ = ros::master::getURI();
    me_ = ros::this_node::getName();
    line_.reset(new RpcLine(ros::master::getHost(), static_cast<int>(ros::master::getPort()), wake_[0]));
    pid_ = askPid();  // now, so that a restart from here on is noticed
    rememberServices();
    thread_ = std::thread(&MasterWatch::loop, this);
  }

  /// End the thread at once, whatever it waits for.
  void stop() {
    if (wake_[1] >= 0) {
      char x = 'x';
      (void)!::write(wake_[1], &x, 1);
    }
    if (thread_.joinable()) thread_.join();
    line_.reset();
    for (int& fd : wake_) {
      if (fd >= 0) ::close(fd);
      fd = -1;
    }
  }

 private:
  void loop() {
    bool down = false;
    while (ros::ok()) {
      if (down || line_->fd() < 0) {
        if (waitReady(-1, 0, wake_[0], after(period_)) < 0) return;
      } else {  // readable: the master closed the connection (it died), or it said something unasked
        int w = waitReady(line_->fd(), POLLIN, wake_[0], after(recheck_));
        if (w < 0) return;
        if (w > 0) line_->close();
      }
      long pid = askPid();
      if (pid < 0) {
        if (!down) {
          ROS_WARN("bmtree: the ROS master at %s does not answer; waiting for it to come back", master_uri_.c_str());
        }
        down = true;
        continue;
      }
      if (down || pid != pid_) {
        if (!ros::ok()) return;  // stopping: register nothing
        std::string why = registerAgain();
        if (!why.empty()) {  // the master went away again, or the node is stopping: next period
          ROS_WARN("bmtree: could not register again with the ROS master at %s: %s", master_uri_.c_str(), why.c_str());
          down = true;
          continue;
        }
        pid_ = pid;
      }
      down = false;
    }
  }

  long askPid() {
    XmlRpc::XmlRpcValue answer, pid;
    if (line_->call("getPid", rpcParams({me_}), answer, timeout_) != RpcLine::kOk || !rosValue(answer, pid) ||
        pid.getType() != XmlRpc::XmlRpcValue::TypeInt) {
      line_->close();
      return -1;
    }
    return static_cast<int>(pid);
  }

  /// The services this node provides now (roscpp's logger services, the user's): the master
  /// lists them; roscpp keeps no list of them we could read.
  void rememberServices() {
    XmlRpc::XmlRpcValue answer, state;
    if (line_->call("getSystemState", rpcParams({me_}), answer, timeout_) != RpcLine::kOk || !rosValue(answer, state) ||
        !isArray(state) || state.size() != 3 || !isArray(state[2])) {
      return;
    }
    for (int i = 0; i < state[2].size(); ++i) {
      const XmlRpc::XmlRpcValue& service = state[2][i];  // [name, [node, ...]]
      if (!isArray(service) || service.size() != 2 || !isString(service[0]) || !isArray(service[1])) continue;
      for (int j = 0; j < service[1].size(); ++j) {
        if (isString(service[1][j]) && str(service[1][j]) == me_) services_.push_back(str(service[0]));
      }
    }
  }

  /// Register every topic and service of this node with the master: "" when done, else why not.
  std::string registerAgain() {
    const std::string api = ros::XMLRPCManager::instance()->getServerURI();
    RpcLine master(ros::master::getHost(), static_cast<int>(ros::master::getPort()), wake_[0]);
    RpcLine self("localhost", static_cast<int>(ros::XMLRPCManager::instance()->getServerPort()), wake_[0]);
    XmlRpc::XmlRpcValue answer, pubs, subs, bus, value;
    if (self.call("getPublications", rpcParams({me_}), answer, timeout_) != RpcLine::kOk || !rosValue(answer, pubs) ||
        self.call("getSubscriptions", rpcParams({me_}), answer, timeout_) != RpcLine::kOk || !rosValue(answer, subs) ||
        self.call("getBusInfo", rpcParams({me_}), answer, timeout_) != RpcLine::kOk || !rosValue(answer, bus) ||
        !isArray(pubs) || !isArray(subs) || !isArray(bus)) {
      return "this node's own XML-RPC server did not list its topics";
    }
    for (int i = 0; i < pubs.size(); ++i) {  // publishers first: a subscriber registered next gets them
      if (!isArray(pubs[i]) || pubs[i].size() != 2) continue;
      if (master.call("registerPublisher", rpcParams({me_, pubs[i][0], pubs[i][1], api}), answer, timeout_) !=
              RpcLine::kOk || !rosValue(answer, value)) {
        return "registerPublisher " + str(pubs[i][0]) + " failed";
      }
    }
    for (int i = 0; i < subs.size(); ++i) {
      if (!isArray(subs[i]) || subs[i].size() != 2 || !isString(subs[i][0])) continue;
      const std::string topic = str(subs[i][0]);
      XmlRpc::XmlRpcValue publishers;
      if (master.call("registerSubscriber", rpcParams({me_, subs[i][0], subs[i][1], api}), answer, timeout_) !=
              RpcLine::kOk || !rosValue(answer, publishers) || !isArray(publishers)) {
        return "registerSubscriber " + topic + " failed";
      }
      std::set<std::string> uris;
      for (int j = 0; j < publishers.size(); ++j) {
        if (isString(publishers[j])) uris.insert(str(publishers[j]));
      }
      for (int j = 0; j < bus.size(); ++j) {  // [id, publisher URI, "i", transport, topic, ...]: connected now
        const XmlRpc::XmlRpcValue& c = bus[j];
        if (isArray(c) && c.size() >= 5 && isString(c[1]) && isString(c[2]) && isString(c[4]) && str(c[2]) == "i" &&
            str(c[4]) == topic) {
          uris.insert(str(c[1]));
        }
      }
      XmlRpc::XmlRpcValue list;
      list.setSize(0);
      for (const auto& uri : uris) list[list.size()] = uri;
      // roscpp's own publisherUpdate (TopicManager::pubUpdate is private): connects to the new ones
      if (self.call("publisherUpdate", rpcParams({std::string("/master"), subs[i][0], list}), answer, timeout_) !=
          RpcLine::kOk) {
        return "publisherUpdate " + topic + " failed";
      }
    }
    const std::string service_uri = "rosrpc://" + ros::network::getHost() + ":" +
                                    std::to_string(ros::ConnectionManager::instance()->getTCPPort());
    std::size_t services = 0;
    for (const auto& service : services_) {
      if (!ros::ServiceManager::instance()->lookupServicePublication(service)) continue;  // shut down since
      if (master.call("registerService", rpcParams({me_, service, service_uri, api}), answer, timeout_) !=
              RpcLine::kOk || !rosValue(answer, value)) {
        return "registerService " + service + " failed";
      }
      ++services;
    }
    ROS_WARN("bmtree: registered again with the restarted ROS master at %s (%d publications, %d subscriptions, "
             "%zu services)", master_uri_.c_str(), pubs.size(), subs.size(), services);
    return "";
  }

  const double period_, timeout_, recheck_;
  std::string master_uri_;
  std::string me_;
  std::unique_ptr<RpcLine> line_;  // getPid, kept open
  std::vector<std::string> services_;
  long pid_ = -1;
  int wake_[2] = {-1, -1};  // stop() writes to [1]; every wait also watches [0]
  std::thread thread_;
};

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

#endif  // BMTREE_MASTER_WATCH_H

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
// Its own small XML-RPC client (detail/rpc_line.h), not roscpp's: roscpp's waits without a time limit (a master
// machine that vanished would hold the thread, and the node's exit, for minutes), and every wait
// here is also cut short by stop(). The library sets no parameters, so there are none to set again.
// What it cannot get back: parameters set by others (launch files, `rosparam`, private
// `_name:=value` arguments: the node keeps the values it read at start), services advertised after
// the module was made, and messages published while nobody was connected.
//
// CallerWatch (caller_watch.h) asks the same way whether the node that sent the running call (a
// bridge) is still there.
#ifndef BMTREE_MASTER_WATCH_H
#define BMTREE_MASTER_WATCH_H

#include <ros/connection_manager.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <ros/service_manager.h>
#include <ros/xmlrpc_manager.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstring>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "detail/rpc_line.h"

namespace bmtree {
namespace detail {

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

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_MASTER_WATCH_H

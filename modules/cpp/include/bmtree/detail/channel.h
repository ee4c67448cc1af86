// bmtree C++ basic modules, internal: one data topic of a module (its publisher, its subscriber,
// the messages received for the next call), and the topic's name. Part of <bmtree/basic_module.h>,
// which includes it: include that one.
#ifndef BMTREE_DETAIL_CHANNEL_H
#define BMTREE_DETAIL_CHANNEL_H

#include <ros/message_event.h>
#include <ros/message_traits.h>
#include <ros/node_handle.h>
#include <ros/this_node.h>
#include <ros/transport_hints.h>

#include <cctype>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace bmtree {

/// The data topic of a ROS type in module `module`: "std_msgs/Float64" -> "/module/float64".
inline std::string dataTopic(const std::string& module, const std::string& datatype) {
  std::string base = datatype.substr(datatype.rfind('/') + 1);
  for (char& c : base) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return "/" + module + "/" + base;
}

namespace detail {

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

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_CHANNEL_H

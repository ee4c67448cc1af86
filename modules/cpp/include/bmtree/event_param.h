// bmtree C++ basic modules: bmtree::EventParam, one param of an event for BasicModule::emit(). Part
// of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_EVENT_PARAM_H
#define BMTREE_EVENT_PARAM_H

#include <ros/message_traits.h>
#include <ros/serialization.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "detail/text.h"

namespace bmtree {

class BasicModule;

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

}  // namespace bmtree

#endif  // BMTREE_EVENT_PARAM_H

// A C++ basic module written with bmtree's library: a two-finger gripper.
// Definition: gripper.json beside this file. Run it with the bridge:
//   ./gripper &  bmtree-bridge --definition gripper.json
#include <bmtree/basic_module.h>

#include <geometry_msgs/Point.h>
#include <ros/callback_queue.h>
#include <std_msgs/Bool.h>
#include <std_msgs/Float64.h>
#include <std_msgs/String.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <tuple>

class Gripper : public bmtree::BasicModule {
 public:
  explicit Gripper(ros::NodeHandle nh) : BasicModule(nh, "gripper"), sensor_spinner_(1, &sensor_queue_) {
    provide("set_fingers", &Gripper::setFingers, {"opening", "success"});
    provide("reach", &Gripper::reach, {"final_pos", "distance"});
    provide("squeeze", &Gripper::squeeze, {"closed_for", "label"});
    provide("ping", &Gripper::ping, {"success"});
    // The fingers' force sensor (/gripper/contact, N): its callback runs in a thread of its own, so
    // it is heard while a function runs too, and a firm touch becomes the event "touched".
    ros::NodeHandle sensor(nh);
    sensor.setCallbackQueue(&sensor_queue_);
    contact_ = sensor.subscribe("/" + moduleName() + "/contact", 10, &Gripper::onContact, this);
    sensor_spinner_.start();
  }

  // In the sensor's thread: the event "touched" of gripper.json, with its params force and position.
  void onContact(const std_msgs::Float64& force) {
    if (!(force.data >= 1.0)) return;  // a brush, or noise (NaN too)
    geometry_msgs::Point position;
    {
      std::lock_guard<std::mutex> lock(mutex_);  // reach() writes it in the function's thread
      position = position_;
    }
    emit("touched", {{"force", force}, {"position", position}});
  }

  std::tuple<std_msgs::Float64, std_msgs::Bool> setFingers(const std_msgs::Float64& left,
                                                          const std_msgs::Float64& right) {
    if (left.data > right.data) throw bmtree::Failure("the left finger must stay left of the right one");
    std_msgs::Float64 opening;
    opening.data = right.data - left.data;
    std_msgs::Bool ok;
    ok.data = true;
    return std::make_tuple(opening, ok);
  }

  std::tuple<geometry_msgs::Point, std_msgs::Float64> reach(const geometry_msgs::Point& target) {
    std_msgs::Float64 distance;
    distance.data = std::sqrt(target.x * target.x + target.y * target.y + target.z * target.z);
    if (distance.data > 1.0) throw bmtree::Rejected("the target is out of reach (more than 1 m away)");
    {
      std::lock_guard<std::mutex> lock(mutex_);
      position_ = target;
    }
    return std::make_tuple(target, distance);
  }

  // Stands for a slow motion: the spinner thread is busy meanwhile, as a real driver call would be.
  // sleepFor() returns false as soon as the call is cancelled (the tree halted it): a real driver
  // would stop the motors here and return.
  std::tuple<std_msgs::Float64, std_msgs::String> squeeze(const std_msgs::Float64& seconds,
                                                         const std_msgs::String& label) {
    if (!(seconds.data >= 0 && seconds.data <= 60)) throw bmtree::Failure("seconds must be within 0..60");  // NaN too
    auto start = std::chrono::steady_clock::now();
    if (!sleepFor(seconds.data)) ROS_INFO("gripper: squeeze cancelled, fingers stopped");
    std_msgs::Float64 closed_for;
    closed_for.data = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!cancelled()) closed_for.data = seconds.data;
    return std::make_tuple(closed_for, label);
  }

  std::tuple<std_msgs::Bool> ping() {
    std_msgs::Bool ok;
    ok.data = true;
    return std::make_tuple(ok);
  }

 private:
  std::mutex mutex_;
  geometry_msgs::Point position_;  // where reach() brought the gripper
  ros::CallbackQueue sensor_queue_;
  ros::AsyncSpinner sensor_spinner_;  // declared after its queue: it stops before the queue goes
  ros::Subscriber contact_;           // and it stops first of all
};

int main(int argc, char** argv) { return bmtree::run<Gripper>(argc, argv, "gripper"); }

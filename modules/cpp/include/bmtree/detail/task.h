// bmtree C++ basic modules, internal: a function to run on a ROS callback queue. Part of
// <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_DETAIL_TASK_H
#define BMTREE_DETAIL_TASK_H

#include <ros/callback_queue_interface.h>

#include <functional>
#include <utility>

namespace bmtree {
namespace detail {

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

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_TASK_H

// bmtree C++ basic modules: a module is a class with one method per function.
//
// Speaks the original C++ basic-module protocol (manual section 4.3) to a bridge node
// (bmtree-bridge, or the original one): data topics /<BM>/<type> carry the values,
// /<BM>/BM_input and /<BM>/BM_output synchronise. Header-only, C++14, no sleeps, no
// rospack at run time.
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
// Threads: a function runs in the thread that spins the node's callback queue (with run(): the
// main thread, inside ros::spin()), one call at a time. While it runs, that thread runs no other
// callback of the queue: your own subscriptions and timers on it wait until the function has
// returned. Do not call ros::spinOnce() inside a function (the library's own callbacks that it would
// run are put off until the function returns); give your own topics a ros::CallbackQueue of their
// own (spin it with callAvailable(), or an AsyncSpinner). Service calls and publishing are fine,
// except a call to a service this node serves on the queue the function holds (it cannot answer).
// A custom main() with a MultiThreadedSpinner or AsyncSpinner on the global queue works too: the
// library still runs one function at a time (a BM_input that arrives meanwhile waits for it).
//
// What it does beyond the original utility: its inputs are only the data messages of the node
// that sent BM_input (connection header callerid: not its own outputs, not a third node's);
// the i-th such message received on a topic for a call is the i-th
// input listed on that topic, so two inputs of one type keep their values; a BM_input that
// overtook its inputs waits for them, bounded by ~input_wait (1 s). A call of bmtree-bridge
// (it carries a call_id) whose inputs did not all arrive is answered "failed" naming them, without
// running the function; a call of the original bridge runs with the last values received, as the
// original did, and a warning names the stale inputs. A function that throws bmtree::Failure /
// bmtree::Rejected (or any exception) answers BM_output with "error" and "status" keys, which
// bmtree-bridge reports and the original bridge ignores; other exceptions are logged with their
// type. An unknown function is answered with an error instead of silence; /<BM>/BM_info (latched)
// tells a bridge that this library is on the other side, so it needs no gap between the inputs and
// BM_input.
//
// Cancels: a bridge that gives up on a call (the tree halted it, or its --call-timeout passed)
// publishes {"call_id": ...} on /<BM>/BM_cancel. That topic is served by a thread of its own, so
// a cancel arrives while the function runs: a long function polls cancelled(), waits with
// sleepFor(seconds), or registers onCancel(callback), stops the hardware and returns; its answer then
// says "cancelled" (the bridge throws its outputs away) and the module takes calls again at once. A
// call cancelled before it started is answered "cancelled" without running. The original bridge
// sends no cancels. A call whose caller is gone (the bridge was killed: its connection to BM_output
// dropped, and its XML-RPC port refuses or answers with another pid) is cancelled the same way, and
// the node logs it ("cancelled call ... of arm.move_to: its caller /arm_bridge is gone (...)").
//
// Events: emit() publishes an event of the module's definition ("Events"), from any thread (a
// ros::Timer, a subscriber's callback, a thread of your own, a function while it runs):
//
//   std_msgs::String name;  name.data = "Ana";
//   geometry_msgs::Point where;  where.x = 1.0;
//   emit("personSeen", {{"name", name}, {"position", where}});   // false if it could not be sent
//
// Each param is a ROS message (bmtree::EventParam: a name and any message type; a double or a
// char* does not compile), serialized at once. The event travels as one message on
// /<BM>/BM_event (std_msgs/String: JSON with the event's name and, per param, its name, ROS type,
// md5sum and serialized bytes in base64), never on the data topics, so it cannot be taken for a
// call's output. bmtree-bridge checks it against the definition (unknown event or param, missing
// param, another type: it logs a warning naming this node and drops it) and publishes it as a bmtree
// event, which a tree's wait_event takes. Nothing is sent while no bridge is connected.
//
// A restarted ROS master is survived (master_watch.h): the module registers its topics again.
//
// This is the one header a module includes; it includes the library's others, each one part:
//   api.h                  BMTREE_CPP_API, the library's API level
//   errors.h               bmtree::Failure, bmtree::Rejected
//   cancel_hook.h          bmtree::CancelHook, what onCancel() returns
//   event_param.h          bmtree::EventParam, one param of emit()
//   basic_module_class.h   the class bmtree::BasicModule: its API, its templates, its members
//   basic_module_calls.h   ... its topics, BM_input, running a call and answering it, BM_info, events
//   basic_module_cancels.h ... cancels, onCancel() callbacks, a call whose caller is gone
//   run.h                  bmtree::run(), a module's main()
//   master_watch.h         surviving a restarted ROS master
//   caller_watch.h         whether the node that sent the running call is still there
//   detail/                internals: channel.h (a data topic), waker.h (the end of an input wait),
//                          task.h, rpc_line.h (XML-RPC client of the watches), text.h, stdout.h
#ifndef BMTREE_BASIC_MODULE_H
#define BMTREE_BASIC_MODULE_H

#include "api.h"
#include "detail/stdout.h"
#include "errors.h"
#include "cancel_hook.h"
#include "event_param.h"
#include "master_watch.h"
#include "caller_watch.h"
#include "basic_module_class.h"
#include "basic_module_calls.h"
#include "basic_module_cancels.h"
#include "run.h"

#endif  // BMTREE_BASIC_MODULE_H

// A C++ module that misbehaves the ways a real driver may: the library's tests build it
// (cmake -DBMTREE_TEST_MODULE=tests/data/cpp/oddities.cpp), never users.
#include <bmtree/basic_module.h>

#include <std_msgs/Bool.h>
#include <std_msgs/Float64.h>
#include <std_msgs/String.h>

#include <array>
#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <tuple>

class Oddities : public bmtree::BasicModule {
 public:
  Oddities(ros::NodeHandle nh, bool bad_names) : BasicModule(nh, "oddities") {
    provide("vendor", &Oddities::vendor, {"success"});
    provide("ok", &Oddities::ok, {"success"});
    provide("stubborn", &Oddities::stubborn, {"slept"});
    // two outputs, one name: a mistake that only shows when the node starts when the names are a
    // std::array (given as {"success"} it is a compile error)
    const std::array<std::string, 2> one_name = {{"success"}};
    if (bad_names) provide("two", &Oddities::two, one_name);
  }

  std::tuple<std_msgs::Bool> vendor() {
    throw "the vendor's driver threw a C string";  // not a std::exception
  }

  std::tuple<std_msgs::Bool> ok() {
    std_msgs::Bool b;
    b.data = true;
    return std::make_tuple(b);
  }

  // Blocks its thread and never looks at cancelled(): a cancel cannot shorten it.
  std::tuple<std_msgs::Float64> stubborn(const std_msgs::Float64& seconds) {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds.data));
    return std::make_tuple(seconds);
  }

  std::tuple<std_msgs::Bool, std_msgs::String> two() { return std::make_tuple(std_msgs::Bool(), std_msgs::String()); }
};

static bool bad_names = false;

class Chosen : public Oddities {
 public:
  explicit Chosen(ros::NodeHandle nh) : Oddities(nh, bad_names) {}
};

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) bad_names = bad_names || std::strcmp(argv[i], "--bad-names") == 0;
  return bmtree::run<Chosen>(argc, argv, "oddities");
}

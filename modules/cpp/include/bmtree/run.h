// bmtree C++ basic modules: bmtree::run(), a module's main(). Part of <bmtree/basic_module.h>,
// which includes it: include that one.
#ifndef BMTREE_RUN_H
#define BMTREE_RUN_H

#include <ros/ros.h>

#include <cctype>
#include <stdexcept>
#include <string>

namespace bmtree {

/// The node's name: `module`, or the new module name of a `_basic_mod:=NAME` argument, so that
/// two copies of one module renamed that way do not knock each other off the master (an
/// explicit `__name:=` still wins, in ros::init).
inline std::string nodeNameFor(int argc, char** argv, const std::string& module) {
  const std::string key = "_basic_mod:=";
  std::string name = module;
  for (int i = 1; i < argc; ++i) {
    std::string arg(argv[i]);
    if (arg.compare(0, key.size(), key) == 0 && arg.size() > key.size()) name = arg.substr(key.size());
  }
  // a node name is a ROS name: a letter, then letters, digits and '_' (else ros::init would throw)
  bool valid = !name.empty() && std::isalpha(static_cast<unsigned char>(name[0]));
  for (char c : name) valid = valid && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
  return valid ? name : module;
}

/// ros::init (the node is named `module`, as the original modules were, or after
/// `_basic_mod:=NAME`), construct the module, spin until shutdown. Returns the process exit code.
template <class Module>
int run(int argc, char** argv, const std::string& module) {
  ros::init(argc, argv, nodeNameFor(argc, argv, module));
  ros::NodeHandle nh;
  try {
    Module m(nh);
    ROS_INFO("bmtree: C++ basic module %s ready", m.moduleName().c_str());
    ros::spin();
  } catch (const std::logic_error& e) {
    ROS_FATAL("bmtree: %s", e.what());
    return 2;
  }
  return 0;
}

}  // namespace bmtree

#endif  // BMTREE_RUN_H

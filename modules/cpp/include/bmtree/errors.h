// bmtree C++ basic modules: the exceptions a function throws to answer other than "success".
// Part of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_ERRORS_H
#define BMTREE_ERRORS_H

#include <stdexcept>
#include <string>

namespace bmtree {

/// Throw from a function to answer "failed" with a reason.
class Failure : public std::runtime_error {
 public:
  explicit Failure(const std::string& what) : std::runtime_error(what) {}
};

/// Throw from a function to answer "rejected": the call cannot be taken now.
class Rejected : public std::runtime_error {
 public:
  explicit Rejected(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace bmtree

#endif  // BMTREE_ERRORS_H

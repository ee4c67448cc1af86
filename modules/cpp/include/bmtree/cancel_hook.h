// bmtree C++ basic modules: bmtree::CancelHook, what BasicModule::onCancel() returns. Its reset()
// is defined with the module's cancel side (basic_module_cancels.h, included below). Part of
// <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_CANCEL_HOOK_H
#define BMTREE_CANCEL_HOOK_H

#include <cstdint>

namespace bmtree {

class BasicModule;

/// What onCancel() returns: the callback stays registered while this object lives (at most until
/// the call ends). Keep it in a local variable declared after what the callback uses: its
/// destructor unregisters the callback and waits for it if it is running, so the callback never
/// sees those objects destroyed. If the call was cancelled and the callback has not run yet (the
/// function saw the cancel first), the destructor runs it, in its own thread: a callback of a
/// cancelled call runs once, always.
class CancelHook {
 public:
  CancelHook() = default;
  CancelHook(CancelHook&& other) noexcept : owner_(other.owner_), id_(other.id_) { other.owner_ = nullptr; }
  CancelHook& operator=(CancelHook&& other) noexcept {
    if (this != &other) {
      reset();
      owner_ = other.owner_;
      id_ = other.id_;
      other.owner_ = nullptr;
    }
    return *this;
  }
  CancelHook(const CancelHook&) = delete;
  CancelHook& operator=(const CancelHook&) = delete;
  ~CancelHook() { reset(); }
  /// Unregister the callback now (waits for it if it is running in another thread; runs it here if
  /// the call was cancelled and it has not run yet).
  inline void reset();

 private:
  friend class BasicModule;
  CancelHook(BasicModule* owner, std::uint64_t id) : owner_(owner), id_(id) {}
  BasicModule* owner_ = nullptr;
  std::uint64_t id_ = 0;
};

}  // namespace bmtree

// reset() needs the whole BasicModule: it is defined with the module's cancel side
#include "basic_module_class.h"

#endif  // BMTREE_CANCEL_HOOK_H

// bmtree C++ basic modules, internal: stdout is made line-buffered before main(). Part of
// <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_DETAIL_STDOUT_H
#define BMTREE_DETAIL_STDOUT_H

#include <cstdio>

namespace bmtree {
namespace detail {

/// A module's output mostly goes to a log file (roslaunch, systemd), where stdout is
/// block-buffered: prints (ROS_INFO too) would show up kilobytes late, or never after a kill.
/// Set before main(), so before any output.
inline bool lineBufferedStdout() { return std::setvbuf(stdout, nullptr, _IOLBF, 0) == 0; }
static const bool kStdoutLineBuffered = lineBufferedStdout();

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_STDOUT_H

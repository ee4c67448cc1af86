// bmtree C++ basic modules, internal: text for messages and payloads (a type's readable name,
// base64, seconds). Part of <bmtree/basic_module.h>, which includes it: include that one.
#ifndef BMTREE_DETAIL_TEXT_H
#define BMTREE_DETAIL_TEXT_H

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>
#include <typeinfo>

#if defined(__GNUG__)
#include <cxxabi.h>
#endif

namespace bmtree {
namespace detail {

/// The readable name of a type: "std::runtime_error", not "St13runtime_error".
inline std::string typeName(const std::type_info* type) {
  if (type == nullptr) return "an unknown type";
#if defined(__GNUG__)
  int status = 0;
  char* name = abi::__cxa_demangle(type->name(), nullptr, nullptr, &status);
  if (status == 0 && name != nullptr) {
    std::string out(name);
    std::free(name);
    return out;
  }
  std::free(name);
#endif
  return type->name();
}

/// Standard base64 (RFC 4648, with padding) of `n` bytes.
inline std::string base64(const std::uint8_t* data, std::size_t n) {
  static const char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((n + 2) / 3 * 4);
  for (std::size_t i = 0; i < n; i += 3) {
    const std::uint32_t b0 = data[i];
    const std::uint32_t b1 = i + 1 < n ? data[i + 1] : 0u;
    const std::uint32_t b2 = i + 2 < n ? data[i + 2] : 0u;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kDigits[(v >> 18) & 63u];
    out += kDigits[(v >> 12) & 63u];
    out += i + 1 < n ? kDigits[(v >> 6) & 63u] : '=';
    out += i + 2 < n ? kDigits[v & 63u] : '=';
  }
  return out;
}

/// "1", "0.3": seconds as a person writes them.
inline std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_TEXT_H

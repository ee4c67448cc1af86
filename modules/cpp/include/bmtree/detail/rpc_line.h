// bmtree C++ basic modules, internal: a small XML-RPC client for the master watch and the caller
// watch (master_watch.h, caller_watch.h). Not roscpp's: roscpp's waits without a time limit (a
// master machine that vanished would hold the thread, and the node's exit, for minutes); every wait
// here is bounded and also cut short by the watch's wake pipe. Part of <bmtree/basic_module.h>,
// which includes it: include that one.
#ifndef BMTREE_DETAIL_RPC_LINE_H
#define BMTREE_DETAIL_RPC_LINE_H

#include <xmlrpcpp/XmlRpcException.h>
#include <xmlrpcpp/XmlRpcUtil.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdlib>
#include <initializer_list>
#include <string>
#include <utility>

namespace bmtree {
namespace detail {

using WatchClock = std::chrono::steady_clock;

inline WatchClock::time_point after(double seconds) {
  return WatchClock::now() + std::chrono::duration_cast<WatchClock::duration>(std::chrono::duration<double>(seconds));
}

/// Wait until `fd` has `events` (or an error), `wake` is readable or `deadline` passes: 1 ready,
/// 0 timed out, -1 woken. `fd` < 0 waits on `wake` alone.
inline int waitReady(int fd, short events, int wake, WatchClock::time_point deadline) {
  for (;;) {
    auto us = std::chrono::duration_cast<std::chrono::microseconds>(deadline - WatchClock::now()).count();
    long long ms = std::max<long long>(0, std::min<long long>((us + 999) / 1000, 1 << 30));  // not 0 before the end
    pollfd fds[2] = {{wake, POLLIN, 0}, {fd, events, 0}};
    int n = ::poll(fds, fd >= 0 ? 2 : 1, static_cast<int>(ms));
    if (n < 0 && errno == EINTR) continue;  // roscpp's SIGINT handler
    if (n < 0 || fds[0].revents != 0) return -1;
    if (n > 0) return 1;
    if (WatchClock::now() >= deadline) return 0;
  }
}

/// One HTTP connection to an XML-RPC server (the master, or this node's own), kept open when the
/// server keeps it; every wait is bounded and cut short by the watch's wake pipe.
class RpcLine {
 public:
  enum Result { kOk, kBroken, kTimeout, kStopped };

  RpcLine(std::string host, int port, int wake) : host_(std::move(host)), port_(port), wake_(wake) {}
  ~RpcLine() { close(); }
  RpcLine(const RpcLine&) = delete;
  RpcLine& operator=(const RpcLine&) = delete;

  /// The kept connection (-1 when none): readable once the server closed it.
  int fd() const { return fd_; }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

  /// Call `method` with the array `params`; kOk with the answer's value in `result`.
  Result call(const std::string& method, const XmlRpc::XmlRpcValue& params, XmlRpc::XmlRpcValue& result,
              double timeout) {
    std::string body = "<?xml version=\"1.0\"?>\r\n<methodCall><methodName>" + method + "</methodName>\r\n<params>";
    for (int i = 0; i < params.size(); ++i) body += "<param>" + params[i].toXml() + "</param>";
    body += "</params></methodCall>\r\n";
    const std::string request = "POST / HTTP/1.1\r\nHost: " + host_ + ":" + std::to_string(port_) +
                                "\r\nUser-Agent: bmtree\r\nContent-Type: text/xml\r\nContent-Length: " +
                                std::to_string(body.size()) + "\r\n\r\n" + body;
    const auto deadline = after(timeout);
    for (bool fresh : {fd_ < 0, true}) {  // a kept connection closed meanwhile: once more, afresh
      if (fd_ < 0) {
        Result r = open(deadline);
        if (r != kOk) return r;
      }
      std::string answer;
      Result r = exchange(request, answer, deadline);
      if (r == kOk) return parse(answer, result) ? kOk : kBroken;
      close();
      if (r != kBroken || fresh) return r;
    }
    return kBroken;
  }

 private:
  Result open(WatchClock::time_point deadline) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    if (::getaddrinfo(host_.c_str(), std::to_string(port_).c_str(), &hints, &found) != 0) return kBroken;
    Result r = kBroken;
    for (addrinfo* a = found; a != nullptr && r == kBroken; a = a->ai_next) {
      int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
      if (fd < 0) continue;
      if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
        r = kOk;
      } else if (errno == EINPROGRESS) {
        int w = waitReady(fd, POLLOUT, wake_, deadline);
        r = w > 0 ? kBroken : w == 0 ? kTimeout : kStopped;
        int err = 0;
        socklen_t len = sizeof(err);
        if (w > 0 && ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0) r = kOk;
      }
      if (r == kOk) {
        fd_ = fd;
        keepalive(fd);
      } else {
        ::close(fd);
      }
    }
    ::freeaddrinfo(found);
    return r;
  }

  /// Let the kernel probe an idle connection, so that a vanished master machine is noticed (~11 s).
  static void keepalive(int fd) {
    int on = 1, idle = 5, interval = 2, count = 3;
    ::setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &on, sizeof(on));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPIDLE, &idle, sizeof(idle));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPINTVL, &interval, sizeof(interval));
    ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPCNT, &count, sizeof(count));
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
  }

  /// Send `request`, read the answer's body; the connection stays open if the server keeps it.
  Result exchange(const std::string& request, std::string& body, WatchClock::time_point deadline) {
    for (std::size_t sent = 0; sent < request.size();) {
      ssize_t n = ::send(fd_, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);  // no SIGPIPE
      if (n > 0) {
        sent += static_cast<std::size_t>(n);
      } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
        int w = waitReady(fd_, POLLOUT, wake_, deadline);
        if (w <= 0) return w == 0 ? kTimeout : kStopped;
      } else {
        return kBroken;
      }
    }
    std::string in;
    std::size_t header_end = std::string::npos, length = 0;
    bool has_length = false, keep = false;
    for (;;) {
      if (header_end == std::string::npos) {
        header_end = in.find("\r\n\r\n");
        if (header_end == std::string::npos && in.size() > kMaxHeader) return kBroken;
        if (header_end != std::string::npos && !readHeader(in.substr(0, header_end), has_length, length, keep)) {
          return kBroken;
        }
      }
      if (header_end != std::string::npos && has_length && in.size() - header_end - 4 >= length) break;
      char buf[16384];
      ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n > 0) {
        in.append(buf, static_cast<std::size_t>(n));
        if (in.size() > kMaxBody) return kBroken;
      } else if (n == 0) {  // closed: the end of an answer without a length, or a broken one
        if (header_end == std::string::npos || has_length) return kBroken;
        keep = false;
        break;
      } else if (errno == EAGAIN || errno == EINTR) {
        int w = waitReady(fd_, POLLIN, wake_, deadline);
        if (w <= 0) return w == 0 ? kTimeout : kStopped;
      } else {
        return kBroken;
      }
    }
    body = in.substr(header_end + 4, has_length ? length : std::string::npos);
    if (!keep) close();
    return kOk;
  }

  static bool readHeader(std::string header, bool& has_length, std::size_t& length, bool& keep) {
    for (char& c : header) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (header.compare(0, 9, "http/1.1 ") != 0 && header.compare(0, 9, "http/1.0 ") != 0) return false;
    if (header.compare(9, 3, "200") != 0) return false;
    keep = header[7] == '1';  // HTTP/1.1 keeps the connection unless it says otherwise
    std::size_t at = header.find("\r\ncontent-length:");
    if (at != std::string::npos) {
      has_length = true;
      length = std::strtoul(header.c_str() + at + 17, nullptr, 10);
    }
    if (header.find("\r\nconnection: close") != std::string::npos) keep = false;
    if (header.find("\r\nconnection: keep-alive") != std::string::npos) keep = true;
    keep = keep && has_length;
    return true;
  }

  static bool parse(const std::string& answer, XmlRpc::XmlRpcValue& result) {
    int offset = 0;
    try {  // <methodResponse><params><param><value>; a <fault> is no answer
      return XmlRpc::XmlRpcUtil::findTag("<methodResponse>", answer, &offset) &&
             XmlRpc::XmlRpcUtil::nextTagIs("<params>", answer, &offset) &&
             XmlRpc::XmlRpcUtil::nextTagIs("<param>", answer, &offset) && result.fromXml(answer, &offset);
    } catch (const XmlRpc::XmlRpcException&) {
      return false;
    }
  }

  static constexpr std::size_t kMaxHeader = 1 << 16;
  static constexpr std::size_t kMaxBody = 1 << 26;  // getSystemState of a large graph
  std::string host_;
  int port_;
  int wake_;
  int fd_ = -1;
};

/// The value of a ROS API answer [code, message, value] when its code is 1.
inline bool rosValue(const XmlRpc::XmlRpcValue& answer, XmlRpc::XmlRpcValue& value) {
  if (answer.getType() != XmlRpc::XmlRpcValue::TypeArray || answer.size() != 3) return false;
  const XmlRpc::XmlRpcValue& code = answer[0];
  if (code.getType() != XmlRpc::XmlRpcValue::TypeInt || static_cast<const int&>(code) != 1) return false;
  value = answer[2];
  return true;
}

inline XmlRpc::XmlRpcValue rpcParams(std::initializer_list<XmlRpc::XmlRpcValue> values) {
  XmlRpc::XmlRpcValue params;
  params.setSize(static_cast<int>(values.size()));
  int i = 0;
  for (const auto& v : values) params[i++] = v;
  return params;
}

inline bool isArray(const XmlRpc::XmlRpcValue& v) { return v.getType() == XmlRpc::XmlRpcValue::TypeArray; }
inline bool isString(const XmlRpc::XmlRpcValue& v) { return v.getType() == XmlRpc::XmlRpcValue::TypeString; }
inline std::string str(const XmlRpc::XmlRpcValue& v) { return static_cast<const std::string&>(v); }

}  // namespace detail
}  // namespace bmtree

#endif  // BMTREE_DETAIL_RPC_LINE_H

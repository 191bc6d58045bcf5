// Which client a call comes from, for per-client limits (streams per
// client). A client with a token is its principal; without one it is an
// address: the peer's, or, behind a trusted balancer, the address the
// balancer saw (nginx sets it as x-real-ip; see deploy/nginx/). The header
// is only believed from trusted proxies, so clients cannot pick their key.
//
// Thread-safe (immutable after Parse).
#ifndef SWARF_SERVER_CLIENT_ID_H_
#define SWARF_SERVER_CLIENT_ID_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace swarf::server {

// Metadata carrying the client's address, set by a trusted balancer.
inline constexpr char kRealIpMetadata[] = "x-real-ip";

class ProxyTrust {
 public:
  // `spec`: comma-separated IP addresses or CIDR prefixes, IPv4 or IPv6
  // ("127.0.0.1,10.0.0.0/8,fd00::/8"); empty: no proxy is trusted.
  // InvalidArgument naming the bad entry.
  static absl::StatusOr<ProxyTrust> Parse(const std::string& spec);

  // Whether the address `ip` (no port, no brackets) is trusted.
  bool Trusts(const std::string& ip) const;
  bool empty() const { return prefixes_.empty(); }

 private:
  struct Prefix {
    int family = 0;
    uint8_t bytes[16] = {};
    int bits = 0;
  };
  std::vector<Prefix> prefixes_;
};

// A gRPC peer's address without its port: "ipv4:10.1.2.3:5000" -> "10.1.2.3",
// "ipv6:[::1]:5000" -> "::1"; other peers (unix sockets) unchanged.
std::string PeerAddress(const std::string& peer);

// The key a client's streams are counted under: `principal` when not
// empty; otherwise `real_ip` (when not null, an IP address, and the peer a
// trusted proxy); otherwise the peer's address.
std::string ClientKey(const std::string& principal, const std::string& peer,
                      const std::string* real_ip, const ProxyTrust& trust);

}  // namespace swarf::server

#endif  // SWARF_SERVER_CLIENT_ID_H_

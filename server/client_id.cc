#include "server/client_id.h"

#include <arpa/inet.h>

#include <cstring>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace swarf::server {
namespace {

// Parses an IPv4 or IPv6 address into 4 or 16 bytes; the family, or 0.
int ParseIp(const std::string& text, uint8_t bytes[16]) {
  if (inet_pton(AF_INET, text.c_str(), bytes) == 1) return AF_INET;
  if (inet_pton(AF_INET6, text.c_str(), bytes) == 1) return AF_INET6;
  return 0;
}

}  // namespace

absl::StatusOr<ProxyTrust> ProxyTrust::Parse(const std::string& spec) {
  ProxyTrust trust;
  for (absl::string_view entry :
       absl::StrSplit(spec, ',', absl::SkipWhitespace())) {
    entry = absl::StripAsciiWhitespace(entry);
    const std::string text(entry);
    Prefix p;
    const size_t slash = text.find('/');
    p.family = ParseIp(text.substr(0, slash), p.bytes);
    const int max_bits = p.family == AF_INET ? 32 : 128;
    p.bits = max_bits;
    const bool bits_ok =
        slash == std::string::npos ||
        (absl::SimpleAtoi(text.substr(slash + 1), &p.bits) && p.bits >= 0 &&
         p.bits <= max_bits);
    if (p.family == 0 || !bits_ok) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--trusted_proxies: \"", text,
          "\" is not an IP address or CIDR prefix (e.g. 10.0.0.0/8)"));
    }
    trust.prefixes_.push_back(p);
  }
  return trust;
}

bool ProxyTrust::Trusts(const std::string& ip) const {
  uint8_t bytes[16];
  const int family = ParseIp(ip, bytes);
  if (family == 0) return false;
  for (const Prefix& p : prefixes_) {
    if (p.family != family) continue;
    const int whole = p.bits / 8, rest = p.bits % 8;
    if (std::memcmp(bytes, p.bytes, whole) != 0) continue;
    const uint8_t mask = static_cast<uint8_t>(0xFF00 >> rest);
    if (rest == 0 || (bytes[whole] & mask) == (p.bytes[whole] & mask)) {
      return true;
    }
  }
  return false;
}

std::string PeerAddress(const std::string& peer) {
  absl::string_view p = peer;
  if (absl::ConsumePrefix(&p, "ipv4:")) {
    return std::string(p.substr(0, p.rfind(':')));
  }
  if (absl::ConsumePrefix(&p, "ipv6:")) {
    p = p.substr(0, p.rfind(':'));
    absl::ConsumePrefix(&p, "[");
    absl::ConsumeSuffix(&p, "]");
    return std::string(p);
  }
  return peer;
}

std::string ClientKey(const std::string& principal, const std::string& peer,
                      const std::string* real_ip, const ProxyTrust& trust) {
  if (!principal.empty()) return principal;
  const std::string address = PeerAddress(peer);
  uint8_t bytes[16];
  if (real_ip != nullptr && !trust.empty() && trust.Trusts(address) &&
      ParseIp(*real_ip, bytes) != 0) {
    return *real_ip;
  }
  return address;
}

}  // namespace swarf::server

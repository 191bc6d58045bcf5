#include "server/auth.h"

#include <fstream>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "spdlog/spdlog.h"

namespace swarf::server {
namespace {

// Files are checked for changes at most this often.
constexpr absl::Duration kRecheck = absl::Seconds(1);

}  // namespace

std::string TokenStore::Principal(const std::string& token) {
  // 64-bit FNV-1a twice (two offsets): a stable, non-reversible label for
  // a session's owner. Not a password hash: tokens are random secrets.
  uint64_t a = 0xcbf29ce484222325ull, b = 0x84222325cbf29ce4ull;
  for (unsigned char c : token) {
    a = (a ^ c) * 0x100000001b3ull;
    b = (b ^ c) * 0x100000001b3ull;
  }
  return absl::StrFormat("tok-%016x%016x", a, b);
}

absl::StatusOr<std::unique_ptr<TokenStore>> TokenStore::Open(
    const std::string& path) {
  auto s = std::unique_ptr<TokenStore>(new TokenStore(path));
  if (!path.empty()) {
    if (absl::Status st = s->Reload(); !st.ok()) return st;
  }
  return s;
}

absl::Status TokenStore::Reload() {
  std::error_code ec;
  const auto mtime = std::filesystem::last_write_time(path_, ec);
  std::ifstream in(path_);
  if (ec || !in) {
    return absl::FailedPreconditionError(
        absl::StrCat("cannot read --auth_tokens_file ", path_));
  }
  std::set<std::string> principals;
  std::string line;
  while (std::getline(in, line)) {
    std::string token(absl::StripAsciiWhitespace(line));
    if (token.empty() || token[0] == '#') continue;
    principals.insert(Principal(token));
  }
  absl::MutexLock l(&mu_);
  if (principals != principals_ && !principals_.empty()) {
    spdlog::info("auth: {} token(s) now (file changed)", principals.size());
  }
  principals_ = std::move(principals);
  mtime_ = mtime;
  return absl::OkStatus();
}

absl::StatusOr<std::string> TokenStore::Check(
    const std::string& authorization) {
  if (path_.empty()) return std::string();
  bool stale = false;
  {
    absl::MutexLock l(&mu_);
    const absl::Time now = absl::Now();
    if (now - last_check_ > kRecheck) {
      last_check_ = now;
      std::error_code ec;
      stale = std::filesystem::last_write_time(path_, ec) != mtime_ && !ec;
    }
  }
  if (stale) {
    if (absl::Status s = Reload(); !s.ok()) {
      spdlog::warn("auth: {}", std::string(s.message()));  // keep old tokens
    }
  }
  constexpr std::string_view kBearer = "Bearer ";
  if (authorization.rfind(kBearer, 0) != 0) {
    return absl::UnauthenticatedError(
        "authorization metadata \"Bearer <token>\" is required");
  }
  const std::string principal =
      Principal(authorization.substr(kBearer.size()));
  absl::MutexLock l(&mu_);
  if (!principals_.count(principal)) {
    return absl::UnauthenticatedError("the token is not valid");
  }
  return principal;
}

}  // namespace swarf::server

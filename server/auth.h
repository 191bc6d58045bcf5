// Bearer-token authentication. Tokens live in a file, one per line (blank
// lines and lines starting with '#' are skipped); the file is read again
// when it changes, so tokens can be added or revoked without a restart.
//
// A caller's identity ("principal") is a digest of its token, never the
// token itself: sessions record the principal that created them, and
// journals store it.
//
// Thread-safe.
#ifndef SWARF_SERVER_AUTH_H_
#define SWARF_SERVER_AUTH_H_

#include <filesystem>
#include <set>
#include <string>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"

namespace swarf::server {

class TokenStore {
 public:
  // `path` empty: authentication is off and every caller is "".
  static absl::StatusOr<std::unique_ptr<TokenStore>> Open(
      const std::string& path);

  bool enabled() const { return !path_.empty(); }

  // The principal of the `authorization` metadata value ("Bearer <token>"),
  // or UNAUTHENTICATED when it is missing or not a current token.
  absl::StatusOr<std::string> Check(const std::string& authorization);

  // Reads the file again now (also done by Check when the file changed).
  absl::Status Reload();

  // The principal of a token.
  static std::string Principal(const std::string& token);

 private:
  explicit TokenStore(std::string path) : path_(std::move(path)) {}

  const std::string path_;
  absl::Mutex mu_;
  std::set<std::string> principals_ ABSL_GUARDED_BY(mu_);
  std::filesystem::file_time_type mtime_ ABSL_GUARDED_BY(mu_);
  absl::Time last_check_ ABSL_GUARDED_BY(mu_) = absl::InfinitePast();
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_AUTH_H_

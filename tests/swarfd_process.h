// A real swarfd (SWARFD_PATH) as a child process, for the tests of durable
// sessions across restarts (crash_test, legacy_restore_test): started on a
// data directory with its output appended to a log file, on a free loopback
// port read back from that log. Header only; one process per object.
#ifndef SWARF_TESTS_SWARFD_PROCESS_H_
#define SWARF_TESTS_SWARFD_PROCESS_H_

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace swarf::testing {

// Everything in the file at `path` ("" if there is none).
inline std::string ReadFileText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)),
                     std::istreambuf_iterator<char>());
}

class SwarfdProcess {
 public:
  // Starts SWARFD_PATH --listen 127.0.0.1:0 --data_dir=data_dir, then
  // `flags`. port() is 0 if it exited or did not report a port within 60 s
  // (a sanitizer build restoring a session on a loaded machine is slow).
  SwarfdProcess(const std::string& data_dir, const std::string& log,
                const std::vector<std::string>& flags)
      : log_(log) {
    std::vector<std::string> args = {SWARFD_PATH, "--listen", "127.0.0.1:0",
                                     "--data_dir=" + data_dir};
    args.insert(args.end(), flags.begin(), flags.end());
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      dup2(fd, 1);
      dup2(fd, 2);
      execv(SWARFD_PATH, argv.data());
      _exit(127);
    }
    // The port from the log: "listening on ... (port N)".
    const std::regex port_re(R"(\(port (\d+)\))");
    for (int tries = 0; tries < 2400 && port_ == 0; ++tries) {
      std::this_thread::sleep_for(std::chrono::milliseconds(25));
      const std::string text = ReadFileText(log);
      std::smatch m;
      if (std::regex_search(text, m, port_re)) {
        port_ = std::stoi(m[1]);
      } else if (waitpid(pid_, nullptr, WNOHANG) == pid_) {
        pid_ = -1;  // exited: its log says why
        break;
      }
    }
  }
  ~SwarfdProcess() { Kill(); }
  SwarfdProcess(const SwarfdProcess&) = delete;
  SwarfdProcess& operator=(const SwarfdProcess&) = delete;

  int port() const { return port_; }
  // What the process has logged so far.
  std::string Log() const { return ReadFileText(log_); }

  // SIGKILL: no chance to flush or snapshot anything.
  void Kill() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
      pid_ = -1;
    }
  }
  // SIGTERM (drain, snapshot the changed sessions, exit), waiting up to
  // 60 s; then SIGKILL. Whether it exited by itself with status 0.
  bool Stop() {
    if (pid_ <= 0) return false;
    ::kill(pid_, SIGTERM);
    int status = 0;
    for (int tries = 0; tries < 2400; ++tries) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) && WEXITSTATUS(status) == 0;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    Kill();
    return false;
  }

 private:
  std::string log_;
  pid_t pid_ = -1;
  int port_ = 0;
};

}  // namespace swarf::testing

#endif  // SWARF_TESTS_SWARFD_PROCESS_H_

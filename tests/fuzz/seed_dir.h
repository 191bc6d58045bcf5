// Where a seeds program (request_seeds.cc, state_seeds.cc) writes: the
// directory named on its command line, one file per seed.
#ifndef SWARF_TESTS_FUZZ_SEED_DIR_H_
#define SWARF_TESTS_FUZZ_SEED_DIR_H_

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace swarf::fuzz {

class SeedDir {
 public:
  // The directory in argv[1], created if missing; exits with a usage
  // message unless it is the only argument.
  SeedDir(int argc, char** argv) {
    if (argc != 2) {
      std::fprintf(stderr, "usage: %s OUT_DIR\n", argv[0]);
      std::exit(2);
    }
    program_ = std::filesystem::path(argv[0]).filename().string();
    dir_ = argv[1];
    std::filesystem::create_directories(dir_);
  }

  // A seed: the byte that tells the fuzz target what the rest is, then
  // `body`.
  void Write(const std::string& name, char first, std::string_view body) {
    std::ofstream f(dir_ / name, std::ios::binary | std::ios::trunc);
    f.put(first);
    f.write(body.data(), static_cast<std::streamsize>(body.size()));
    if (!f) {
      std::fprintf(stderr, "%s: cannot write %s\n", program_.c_str(),
                   (dir_ / name).c_str());
      std::exit(1);
    }
    ++written_;
  }

  // Says how many seeds were written; main's exit status.
  int Done() const {
    std::printf("%s: %d seeds in %s\n", program_.c_str(), written_,
                dir_.c_str());
    return 0;
  }

 private:
  std::string program_;
  std::filesystem::path dir_;
  int written_ = 0;
};

}  // namespace swarf::fuzz

#endif  // SWARF_TESTS_FUZZ_SEED_DIR_H_

// What every fuzz target and its regression test share: each runXxx feeds raw bytes to one of
// our readers of untrusted files. Returns true when the reader accepted them and false when it
// refused them with paircast::Error; anything else (another exception, a crash, a sanitizer
// report, a hang) is a finding. The libFuzzer mains in fuzz/ and tests/<module>/
// regression_inputs_test.cpp call the same functions, so a kept crash input replays exactly.
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <string_view>

#include "util/error.h"

namespace paircast::fuzz {

// A per-process scratch folder for inputs that must be files ($TMPDIR or /tmp), removed at exit.
inline std::string scratchDir() {
  static const std::string* dir = [] {
    const auto d =
        std::filesystem::temp_directory_path() / ("paircast-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    auto* path = new std::string(d.string());  // never freed: the exit handler still needs it
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(scratchDir(), ec);
    });
    return path;
  }();
  return *dir;
}

// Writes `bytes` to `dir`/`name`, replacing what was there, and returns the path.
inline std::string writeInput(std::string_view bytes, const std::string& dir,
                              const std::string& name) {
  const std::string path = (std::filesystem::path(dir) / name).string();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("fuzz: cannot write " + path);  // not an input's fault
  return path;
}

// Runs `read`; true on success, false on paircast::Error. Other exceptions propagate.
template <class F>
bool acceptedOrRefused(F&& read) {
  try {
    read();
    return true;
  } catch (const Error&) {
    return false;
  }
}

}  // namespace paircast::fuzz

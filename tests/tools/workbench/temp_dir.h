// A fresh folder under the system's temporary directory for one test (removed by the test).
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

namespace m2s::workbench {

inline std::filesystem::path TempDir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("m2s_workbench_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace m2s::workbench

#include "test_paths.h"

#include <filesystem>

#include <unistd.h>

namespace fs = std::filesystem;

namespace rf::test {

std::string data_path(const std::string& relative) {
    return (fs::path(RAYFORGE_TEST_DATA_DIR) / relative).string();
}

std::string cli_path() { return RAYFORGE_CLI_PATH; }

std::string shared_path(const std::string& relative) {
    fs::path p = fs::path(RAYFORGE_SHARED_DIR) / relative;
    return fs::exists(p) ? p.string() : std::string();
}

std::string temp_dir(const std::string& name) {
    // ctest runs tests as parallel processes: the pid keeps their folders apart.
    fs::path p = fs::temp_directory_path() / ("rayforge_test_" + std::to_string(getpid()) + "_" + name);
    fs::remove_all(p);
    fs::create_directories(p);
    return p.string();
}

}  // namespace rf::test

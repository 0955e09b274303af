// Running the built `rayforge` binary from a test: its exit code, stdout and
// stderr (captured to files), optionally behind a wrapper such as
// "timeout 20" or "xvfb-run -a".
#pragma once

#include <string>
#include <vector>

namespace rf::test {

struct CliResult {
    int exit_code = -1;  // -1: killed by a signal
    std::string out;
    std::string err;
};

// Runs `[wrapper] rayforge ARGS` with stdin from /dev/null.
CliResult run_cli(const std::string& args, const std::string& wrapper = "");

std::string read_file(const std::string& path);
std::vector<std::string> lines_of(const std::string& text);

}  // namespace rf::test

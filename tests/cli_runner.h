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

// Runs `[wrapper] rayforge ARGS` with stdin from /dev/null; the exit code is
// the wrapper's when there is one (e.g. 124 from `timeout`).
CliResult run_cli(const std::string& args, const std::string& wrapper = "");
// The same, but the exit code is rayforge's own, whatever the wrapper's
// (xvfb-run may fail while cleaning up after a successful run).
CliResult run_cli_inside(const std::string& wrapper, const std::string& args);

std::string read_file(const std::string& path);
std::vector<std::string> lines_of(const std::string& text);

}  // namespace rf::test

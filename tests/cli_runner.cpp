#include "cli_runner.h"

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "test_paths.h"

namespace rf::test {

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

std::vector<std::string> lines_of(const std::string& text) {
    std::vector<std::string> lines;
    std::stringstream ss(text);
    for (std::string line; std::getline(ss, line);) lines.push_back(line);
    return lines;
}

CliResult run_cli(const std::string& args, const std::string& wrapper) {
    static const std::string dir = temp_dir("cli_runs");
    static int counter = 0;
    const std::string stem = dir + "/" + std::to_string(counter++);
    const std::string out = stem + ".out", err = stem + ".err";
    const std::string command = wrapper + (wrapper.empty() ? "" : " ") + "'" + cli_path() + "' " + args + " >'" +
                                out + "' 2>'" + err + "' </dev/null";
    const int status = std::system(command.c_str());
    CliResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_file(out);
    r.err = read_file(err);
    std::remove(out.c_str());
    std::remove(err.c_str());
    return r;
}

}  // namespace rf::test

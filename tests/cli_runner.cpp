#include "cli_runner.h"

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
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

namespace {

// Runs `command` with its output captured to STEM.out and STEM.err.
CliResult run_cli_command(const std::string& command, const std::string& stem) {
    const std::string out = stem + ".out", err = stem + ".err";
    const std::string line = command + " >'" + out + "' 2>'" + err + "' </dev/null";
    const int status = std::system(line.c_str());
    CliResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_file(out);
    r.err = read_file(err);
    std::remove(out.c_str());
    std::remove(err.c_str());
    return r;
}

}  // namespace

CliResult run_cli(const std::string& args, const std::string& wrapper) {
    static const std::string dir = temp_dir("cli_runs");
    static int counter = 0;
    const std::string stem = dir + "/" + std::to_string(counter++);
    return run_cli_command(wrapper + (wrapper.empty() ? "" : " ") + "'" + cli_path() + "' " + args, stem);
}

CliResult run_cli_inside(const std::string& wrapper, const std::string& args) {
    static const std::string dir = temp_dir("cli_runs_inside");
    static int counter = 0;
    const std::string stem = dir + "/" + std::to_string(counter++);
    const std::string script = stem + ".sh", code = stem + ".code";
    {
        std::ofstream sh(script);
        sh << "'" << cli_path() << "' " << args << "\necho $? > '" << code << "'\n";
    }
    CliResult r = run_cli_command(wrapper + " sh '" + script + "'", stem);
    const std::string status = read_file(code);
    r.exit_code = status.empty() ? -1 : std::stoi(status);
    std::remove(script.c_str());
    std::remove(code.c_str());
    return r;
}

}  // namespace rf::test

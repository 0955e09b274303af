// rayforge: command-line front end. Exit codes: 0 success, 1 a runtime error
// (reported as one line "rayforge: error: <message>" on stderr), 2 a usage error.
#include <CLI/CLI.hpp>

#include <chrono>
#include <exception>
#include <iostream>
#include <string>

#include "commands.h"

namespace rf::cli {
namespace {
const std::chrono::steady_clock::time_point kLaunched = std::chrono::steady_clock::now();
}  // namespace
std::chrono::steady_clock::time_point launch_time() { return kLaunched; }
}  // namespace rf::cli

namespace {

// Messages must stay on one line even when a library's text has newlines.
std::string one_line(std::string message) {
    for (char& c : message)
        if (c == '\n' || c == '\r') c = ' ';
    return message;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"rayforge: a ray tracing engine for large scenes", "rayforge"};
    app.set_version_flag("--version", std::string("rayforge ") + rf::cli::kVersion);
    app.require_subcommand(1);

    rf::cli::InfoArgs info_args;
    rf::cli::RenderArgs render_args;
    CLI::App* info = rf::cli::add_info_command(app, info_args);
    CLI::App* render = rf::cli::add_render_command(app, render_args);
    rf::cli::BuildArgs build_args;
    CLI::App* build = rf::cli::add_build_command(app, build_args);
    rf::cli::BenchArgs bench_args;
    CLI::App* bench = rf::cli::add_bench_command(app, bench_args);
    rf::cli::ViewArgs view_args;
    CLI::App* view = rf::cli::add_view_command(app, view_args);
    rf::cli::ConvertArgs convert_args;
    CLI::App* convert = rf::cli::add_convert_command(app, convert_args);
    rf::cli::GenerateArgs generate_args;
    CLI::App* generate = rf::cli::add_generate_command(app, generate_args);

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        app.exit(e);  // prints the usage error
        return 2;
    } catch (const std::exception& e) {  // an option the engine's parser refused (e.g. --update sideways)
        std::cerr << "rayforge: error: " << one_line(e.what()) << '\n';
        return 1;
    }

    try {
        if (info->parsed()) return rf::cli::run_info(info_args);
        if (render->parsed()) return rf::cli::run_render(render_args);
        if (build->parsed()) return rf::cli::run_build(build_args);
        if (view->parsed()) return rf::cli::run_view(view_args);
        if (convert->parsed()) return rf::cli::run_convert(convert_args);
        if (generate->parsed()) return rf::cli::run_generate(generate_args);
        if (bench->parsed()) {
            std::string command_line = "rayforge";
            for (int i = 1; i < argc; ++i) command_line += std::string(" ") + argv[i];
            return rf::cli::run_bench(bench_args, command_line);
        }
    } catch (const std::exception& e) {
        std::cerr << "rayforge: error: " << one_line(e.what()) << '\n';
        return 1;
    }
    return 2;
}

// Binding a command-line option straight to an engine field: the text is
// checked against the names the engine knows (a usage error, exit 2,
// otherwise) and parsed by the engine's own parse function, so no string
// copy of an option struct is kept.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace rf::cli {

// --NAME with one of `names`, stored as parse(text) in `field`.
template <class T, class Parse>
CLI::Option* add_named_option(CLI::App* cmd, const std::string& name, T& field, Parse parse,
                              const std::vector<std::string>& names, const std::string& help) {
    return cmd->add_option_function<std::string>(name, [&field, parse](const std::string& text) { field = parse(text); },
                                                 help)
        ->check(CLI::IsMember(names));
}

// A validator from an engine parse function that throws rf::Error.
template <class Parse>
CLI::Validator parsed_by(Parse parse, const std::string& what) {
    return CLI::Validator(
        [parse](std::string& text) {
            try {
                (void)parse(text);
                return std::string();
            } catch (const std::exception& e) {
                return std::string(e.what());
            }
        },
        what);
}

}  // namespace rf::cli

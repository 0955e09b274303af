#include "script.h"

#include <cmath>
#include <sstream>

#include "rayforge/core/error.h"
#include "rayforge/scene/camera.h"
#include "camera_controller.h"
#include "text.h"
#include "view_settings.h"

namespace rf::viewer {
namespace {

// How a command's arguments read.
enum class Args {
    None,
    Count,       // a: whole number >= 0
    Seconds,     // a: number >= 0
    TwoNumbers,  // a, b
    OneNumber,   // a
    Walk,        // word: direction, a: seconds, optional "fast"
    Rest,        // rest: the remainder of the line, required
    KeyValue,    // word: key, rest: value
};

struct Grammar {
    const char* name;
    ScriptOp op;
    Args args;
};

constexpr Grammar kGrammar[] = {
    {"wait-passes", ScriptOp::WaitPasses, Args::Count},
    {"wait-frames", ScriptOp::WaitFrames, Args::Count},
    {"wait-idle", ScriptOp::WaitIdle, Args::None},
    {"sleep", ScriptOp::Sleep, Args::Seconds},
    {"orbit", ScriptOp::Orbit, Args::TwoNumbers},
    {"look", ScriptOp::Look, Args::TwoNumbers},
    {"pan", ScriptOp::Pan, Args::TwoNumbers},
    {"dolly", ScriptOp::Dolly, Args::OneNumber},
    {"walk", ScriptOp::Walk, Args::Walk},
    {"fov", ScriptOp::Fov, Args::OneNumber},
    {"camera", ScriptOp::Camera, Args::Rest},
    {"reset", ScriptOp::Reset, Args::None},
    {"bookmark-save", ScriptOp::BookmarkSave, Args::Rest},
    {"bookmark-load", ScriptOp::BookmarkLoad, Args::Rest},
    {"set", ScriptOp::Set, Args::KeyValue},
    {"load", ScriptOp::Load, Args::Rest},
    {"drop", ScriptOp::Drop, Args::Rest},
    {"screenshot", ScriptOp::Screenshot, Args::Rest},
    {"screenshot-window", ScriptOp::ScreenshotWindow, Args::Rest},
    {"expect-error", ScriptOp::ExpectError, Args::Rest},
    {"expect-no-error", ScriptOp::ExpectNoError, Args::None},
    {"print-camera", ScriptOp::PrintCamera, Args::None},
    {"print-stats", ScriptOp::PrintStats, Args::None},
    {"reset-stats", ScriptOp::ResetStats, Args::None},
    {"play", ScriptOp::Play, Args::None},
    {"pause", ScriptOp::Pause, Args::None},
    {"time", ScriptOp::Time, Args::OneNumber},
    {"quit", ScriptOp::Quit, Args::None},
};

// Limits that keep a script from waiting for ever or overflowing.
constexpr double kMaxCount = 1 << 20;
constexpr double kMaxSeconds = 3600.0;

std::string trim(const std::string& s) {
    const size_t first = s.find_first_not_of(" \t\r");
    if (first == std::string::npos) return "";
    return s.substr(first, s.find_last_not_of(" \t\r") - first + 1);
}

std::vector<std::string> words_of(const std::string& s) {
    std::istringstream in(s);
    std::vector<std::string> words;
    for (std::string w; in >> w;) words.push_back(w);
    return words;
}

void expect_words(const std::vector<std::string>& words, size_t count, const char* usage) {
    if (words.size() != count) throw Error(std::string("usage: ") + usage);
}

// Fills `c` from the text after the command name.
void read_arguments(const Grammar& g, const std::string& after, ScriptCommand& c) {
    const std::vector<std::string> words = words_of(after);
    const std::string usage = std::string(g.name) + [&] {
        switch (g.args) {
            case Args::None: return "";
            case Args::Count: return " N";
            case Args::Seconds: return " SECONDS";
            case Args::TwoNumbers: return " X Y";
            case Args::OneNumber: return " X";
            case Args::Walk: return " forward|back|left|right|up|down SECONDS [fast]";
            case Args::Rest: return " TEXT";
            case Args::KeyValue: return " KEY VALUE";
        }
        return "";
    }();
    switch (g.args) {
        case Args::None: expect_words(words, 0, usage.c_str()); break;
        case Args::Count:
            expect_words(words, 1, usage.c_str());
            c.a = parse_number(words[0], "a count");
            if (c.a < 0 || c.a > kMaxCount || c.a != std::floor(c.a))
                throw Error("expected a whole number in 0.." + std::to_string(int(kMaxCount)) + ", got '" + words[0] + "'");
            break;
        case Args::Seconds:
            expect_words(words, 1, usage.c_str());
            c.a = parse_number(words[0], "seconds");
            if (c.a < 0 || c.a > kMaxSeconds) throw Error("seconds must be in 0..3600, got '" + words[0] + "'");
            break;
        case Args::TwoNumbers:
            expect_words(words, 2, usage.c_str());
            c.a = parse_number(words[0]);
            c.b = parse_number(words[1]);
            break;
        case Args::OneNumber:
            expect_words(words, 1, usage.c_str());
            c.a = parse_number(words[0]);
            break;
        case Args::Walk:
            if (words.size() != 2 && !(words.size() == 3 && words[2] == "fast")) throw Error("usage: " + usage);
            (void)parse_walk_direction(words[0]);
            c.word = words[0];
            c.a = parse_number(words[1], "seconds");
            if (c.a < 0 || c.a > kMaxSeconds) throw Error("seconds must be in 0..3600, got '" + words[1] + "'");
            c.fast = words.size() == 3;
            break;
        case Args::Rest:
            c.rest = trim(after);
            if (c.rest.empty()) throw Error("usage: " + usage);
            break;
        case Args::KeyValue: {
            if (words.size() < 2) throw Error("usage: " + usage);
            c.word = words[0];
            c.rest = trim(trim(after).substr(words[0].size()));
            ViewSettings scratch;  // checks the key and that the value parses; the run checks it again in context
            if (c.word != "device") set_setting(scratch, c.word, c.rest);
            else (void)parse_device(c.rest);
            break;
        }
    }
    if (g.op == ScriptOp::Camera) (void)parse_camera(c.rest);
}

}  // namespace

std::string Script::where(const ScriptCommand& command) const { return path + ":" + std::to_string(command.line); }

std::vector<std::string> script_command_names() {
    std::vector<std::string> names;
    for (const Grammar& g : kGrammar) names.emplace_back(g.name);
    return names;
}

Script parse_script(const std::string& text, const std::string& path) {
    Script script;
    script.path = path;
    std::istringstream in(text);
    std::string raw;
    for (int line = 1; std::getline(in, raw); ++line) {
        const std::string body = trim(raw.substr(0, raw.find('#')));
        if (body.empty()) continue;
        const size_t end = body.find_first_of(" \t");
        const std::string name = body.substr(0, end);
        const std::string after = end == std::string::npos ? "" : body.substr(end);
        const Grammar* grammar = nullptr;
        for (const Grammar& g : kGrammar)
            if (name == g.name) grammar = &g;
        const std::string where = path + ":" + std::to_string(line) + ": ";
        if (!grammar) {
            std::string known;
            for (const std::string& n : script_command_names()) known += (known.empty() ? "" : ", ") + n;
            throw Error(where + "unknown command '" + name + "' (known: " + known + ")");
        }
        ScriptCommand command;
        command.op = grammar->op;
        command.line = line;
        command.text = body;
        try {
            read_arguments(*grammar, after, command);
        } catch (const Error& e) {
            throw Error(where + name + ": " + e.what());
        }
        script.commands.push_back(std::move(command));
    }
    return script;
}

Script load_script(const std::string& path) { return parse_script(read_text_file(path, "the script"), path); }

}  // namespace rf::viewer

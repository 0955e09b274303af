// The viewer's script language (--script FILE): one command per line,
// executed in order by the running viewer, for unattended tests and demos.
// '#' starts a comment; blank lines are skipped. The whole file is parsed
// and checked before the window opens, so a typo fails at once with
// "FILE:LINE: ..." rather than half-way through a run.
//
//   wait-passes N            until the image has N passes at full resolution
//   wait-frames N            until N more images have been shown
//   wait-idle                until no scene load or structure build is pending
//   sleep SECONDS
//   orbit YAW PITCH          degrees (as a left drag)
//   look YAW PITCH           degrees (turning the view about the eye)
//   pan DX DY                pixels of the full-resolution image (as a middle drag)
//   dolly STEPS              wheel steps (positive = closer)
//   walk DIRECTION SECONDS [fast]   forward|back|left|right|up|down, moving for that long
//   fov DEGREES
//   camera EX,EY,EZ,TX,TY,TZ,UX,UY,UZ,FOV
//   reset                    the start camera (the R key)
//   bookmark-save NAME | bookmark-load NAME
//   set KEY VALUE            any setting of the panel (view_settings.h)
//   load SCENE               a file, builtin:NAME or a views.json name (the scene switcher)
//   drop FILE                as if FILE were dropped onto the window
//   screenshot FILE          .png: the displayed image; .exr/.pfm: the linear film
//   screenshot-window FILE   the whole window, panel included (.png)
//   expect-error TEXT        the window shows an error containing TEXT
//   expect-no-error
//   print-camera             the camera as a --camera string, on stdout
//   print-stats              the statistics as one JSON line, on stdout
//   reset-stats              start the maxima (latency, window frame time) and rates afresh
//   play | pause             animated scenes: playback (the space key)
//   time SECONDS             animated scenes: show this time (pauses; the time slider)
//   quit
#pragma once

#include <string>
#include <vector>

namespace rf::viewer {

enum class ScriptOp {
    WaitPasses, WaitFrames, WaitIdle, Sleep, Orbit, Look, Pan, Dolly, Walk, Fov, Camera, Reset,
    BookmarkSave, BookmarkLoad, Set, Load, Drop, Screenshot, ScreenshotWindow, ExpectError, ExpectNoError,
    PrintCamera, PrintStats, ResetStats, Play, Pause, Time, Quit,
};

struct ScriptCommand {
    ScriptOp op;
    int line = 0;               // 1-based line in the file
    std::string text;           // the line as written (for messages)
    double a = 0.0, b = 0.0;    // numbers: counts, seconds, degrees, pixels
    std::string word;           // walk direction, setting key
    std::string rest;           // file, scene, setting value, expected text, camera string, bookmark name
    bool fast = false;          // walk ... fast
};

struct Script {
    std::string path;
    std::vector<ScriptCommand> commands;
    // "FILE:LINE" of a command, for messages.
    [[nodiscard]] std::string where(const ScriptCommand& command) const;
};

// Throws rf::Error "PATH:LINE: why" for the first bad line (unknown command,
// missing or malformed argument, unknown setting or bad value).
Script parse_script(const std::string& text, const std::string& path);
Script load_script(const std::string& path);  // also an error when it cannot be read

// The command names, for messages and docs.
std::vector<std::string> script_command_names();

}  // namespace rf::viewer

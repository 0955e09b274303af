// Everything the viewer lets a person change, in one struct, and one table
// of named settings over it: the panel's widgets, the script's
// `set KEY VALUE` and the tests all go through set_setting, so a value is
// parsed, checked and applied the same way whichever way it came. Each
// setting says what changing it costs: a new structure (Rebuild), a fresh
// accumulation (Restart), or only the display (Retone).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "rayforge/render/render.h"
#include "rayforge/render/tone_mapping.h"
#include "rayforge/world.h"

namespace rf::viewer {

struct ViewSettings {
    // The device; the structure (builder, layout, optimizer, parameters, threads); how it follows an
    // animation (unset: the scene's own method); the page caches' budgets of paged scenes.
    WorldOptions world;
    RenderOptions render;   // integrator and its settings, full resolution, passes (spp), threads
    ToneMapping tone;
    float resolution_scale = 1.0f;  // the film is render.width x render.height times this
    int motion_divisor = 0;         // while the camera moves, each side divided by this; 0 = chosen per scene
};

enum class Effect : uint8_t { Retone = 1, Restart = 2, Rebuild = 4 };

struct SettingInfo {
    std::string key;                   // e.g. "builder"
    std::string group;                 // panel section: structure, integrator, image, display, device
    Effect effect;
    std::vector<std::string> choices;  // for named values; empty for numbers and sizes
    std::string help;
};

// What the settings are for. A paged scene brings its structure in its
// file, so the structure settings do not apply to it (what a device can do
// with it is the world's rule: a refused device fails the rebuild).
enum class SceneKind : uint8_t { InCore, Paged };

// Every setting, in panel order.
const std::vector<SettingInfo>& setting_infos();
// nullptr for an unknown key.
const SettingInfo* find_setting(const std::string& key);
// Whether a scene of this kind takes the setting at all (a paged scene
// takes no structure setting).
bool applies_to(const SettingInfo& info, SceneKind scene);

// The value as set_setting reads it (numbers in the shortest form that
// reads back the same).
std::string get_setting(const ViewSettings& settings, const std::string& key);
// Parses and applies `value`; the result is checked with the engine's own
// option checks (check_world_options: ranges, the device, an update method
// the device cannot run). Throws rf::Error naming the key for an unknown
// key, a bad value, or a setting the shown scene's kind does not take (a
// structure setting for a paged scene), leaving `settings` unchanged.
void set_setting(ViewSettings& settings, const std::string& key, const std::string& value,
                 SceneKind scene = SceneKind::InCore);

// What turning `from` into `to` costs: Effect bits, 0 when nothing changed.
unsigned changes_between(const ViewSettings& from, const ViewSettings& to);

// The renderer's options for the film actually rendered: full resolution
// times resolution_scale, or divided by `motion_divisor` for a preview
// while the camera moves (one pass, pixel-centre samples for Whitted, AO
// and normals, so motion stays crisp).
RenderOptions film_options(const ViewSettings& settings, bool preview, int motion_divisor);

// The motion divisor that makes a preview pass take about `target_ms`,
// from the last full-resolution pass time (1..8).
int auto_motion_divisor(double full_pass_ms, double target_ms);

}  // namespace rf::viewer

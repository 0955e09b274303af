// Output of the bench: the stdout tables and the --json file (one record
// per (scene, view, resolution, structure, builder, layout, ray set)).
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

#include "bench_runner.h"

namespace rf::bench {

struct MachineInfo {
    std::string cpu;     // /proc/cpuinfo model name
    int cores = 0;       // hardware threads
    std::string gpu;     // "" when none is known (RunInfo::gpu names the one a run used)
};
MachineInfo machine_info();

// Now, as 2026-12-07T14:40:01Z (the JSON files' "date").
std::string iso_date_utc();

// The tables of one scene's records: builds (ours, Embree's, the GPU rows'),
// then one row per (ray set, device, candidate) with Embree columns, ratios,
// agreement (GPU rows: with the CPU reference) and per-ray traversal counts.
// The header names the camera rays per pixel of each device's sets.
void print_scene_tables(std::ostream& out, const std::vector<BenchRecord>& records, int threads, int repetitions,
                        int build_repetitions);

// Bogolepov et al. / Zlatuška 2009 configurations: per (scene, resolution, candidate) the summed
// trace time of P (primary), PS (+ shadow) and PSR (+ reflection).
void print_configuration_table(std::ostream& out, const std::vector<BenchRecord>& records);

struct RunInfo {
    std::string command;   // the full command line
    std::string preset;    // "" for none
    int threads = 0;
    int repetitions = 0;
    int build_repetitions = 0;
    std::vector<std::string> unimplemented;  // candidate labels asked for but not implemented
    std::vector<std::string> notes;
    std::vector<std::string> devices{"cpu"};  // "cpu", "cuda:N"
    std::string gpu;                          // name of the CUDA device used, "" for none
};

// Writes the JSON file; throws rf::Error when it cannot be written.
void write_json(const std::string& path, const std::vector<BenchRecord>& records, const RunInfo& info);

// 1234567 -> "1,234,567".
std::string thousands(uint64_t value);

}  // namespace rf::bench

#include "bench_report.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <map>
#include <ostream>
#include <thread>

#include <nlohmann/json.hpp>

#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

using Json = nlohmann::json;

std::string format(const char* fmt, double value) {
    if (!std::isfinite(value)) return "-";
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), fmt, value);
    return buffer;
}

std::string pad(const std::string& text, size_t width, bool left = false) {
    if (text.size() >= width) return text;
    return left ? text + std::string(width - text.size(), ' ') : std::string(width - text.size(), ' ') + text;
}


const PeerFigures* peer(const BenchRecord& record, EmbreeQuality quality) {
    for (const PeerFigures& f : record.embree)
        if (f.quality == quality) return &f;
    return nullptr;
}

Json number_or_null(double value) { return std::isfinite(value) ? Json(value) : Json(nullptr); }

// One line per GPU trace launch of the records' kernels (each once).
void print_kernel_resources(std::ostream& out, const std::vector<BenchRecord>& records) {
    std::map<std::string, bool> shown;
    bool header = false;
    for (const BenchRecord& r : records) {
        for (const GpuKernelResources& k : r.kernel_resources) {
            if (shown[k.kernel]) continue;
            shown[k.kernel] = true;
            if (!header) {
                out << "kernel resources (CUDA function attributes; occupancy: resident threads per SM at the "
                       "launch's block size, theoretical):\n";
                header = true;
            }
            char line[256];
            std::snprintf(line, sizeof line,
                          "  %-40s %3d regs %6zu B local %6zu B shared  block %4d  %2d blocks/SM  occupancy %5.1f%%\n",
                          k.kernel.c_str(), k.registers, k.local_bytes, k.shared_bytes, k.block_size, k.blocks_per_sm,
                          100.0 * k.occupancy);
            out << line;
        }
    }
}

Json resources_json(const std::vector<GpuKernelResources>& resources) {
    Json list = Json::array();
    for (const GpuKernelResources& k : resources)
        list.push_back({{"kernel", k.kernel},
                        {"registers", k.registers},
                        {"local_bytes", k.local_bytes},
                        {"shared_bytes", k.shared_bytes},
                        {"max_threads_per_block", k.max_threads_per_block},
                        {"block_size", k.block_size},
                        {"blocks_per_sm", k.blocks_per_sm},
                        {"occupancy", k.occupancy}});
    return list;
}

}  // namespace

std::string iso_date_utc() {
    const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&now, &tm);
    char buffer[32];
    std::strftime(buffer, sizeof(buffer), "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buffer;
}

MachineInfo machine_info() {
    MachineInfo info;
    info.cores = int(std::thread::hardware_concurrency());
    std::ifstream cpuinfo("/proc/cpuinfo");
    std::string line;
    while (std::getline(cpuinfo, line)) {
        if (line.rfind("model name", 0) != 0) continue;
        const size_t colon = line.find(':');
        if (colon != std::string::npos) info.cpu = line.substr(colon + 2);
        break;
    }
    if (info.cpu.empty()) info.cpu = "unknown CPU";
    return info;
}

void print_scene_tables(std::ostream& out, const std::vector<BenchRecord>& records, int threads, int repetitions,
                        int build_repetitions) {
    if (records.empty()) return;
    const BenchRecord& first = records.front();
    const BenchRecord* first_cpu = nullptr;
    const BenchRecord* first_gpu = nullptr;
    bool has_peer = false;
    for (const BenchRecord& r : records) {
        if (!r.is_gpu() && !first_cpu) first_cpu = &r;
        if (r.is_gpu() && !first_gpu) first_gpu = &r;
        has_peer = has_peer || !r.embree.empty();
    }
    out << "\n== " << first.scene << " (" << thousands(first.triangles) << " triangles)";
    if (first_cpu) out << ", " << threads << " threads";
    out << "; medians of " << repetitions << " traces after a warm-up and " << build_repetitions << " builds\n";
    // The sets differ by device: the protocol's GPU rule traces jittered samples.
    out << "camera rays per pixel:";
    if (first_cpu) out << " cpu " << first_cpu->samples_per_pixel << (first_cpu->samples_per_pixel > 1 ? " (jittered)" : " (centre)");
    if (first_gpu)
        out << (first_cpu ? "," : "") << ' ' << first_gpu->device << ' ' << first_gpu->samples_per_pixel
            << (first_gpu->samples_per_pixel > 1 ? " (jittered)" : " (centre)")
            << (first_gpu->gpu.empty() ? "" : " on " + first_gpu->gpu)
            << "; GPU Mrays/s from the kernel time of one launch, rays resident on the device";
    out << '\n';
    const auto row_label = [](const BenchRecord& r) {
        return r.is_gpu() ? r.device + " " + r.candidate.label() : r.candidate.label();
    };
    const size_t label_width = first_gpu ? 32 : 22;

    // Builds: one row per candidate (from its first record) and per Embree quality.
    out << pad("build", label_width, true) << pad("ms", 10) << pad("layout ms", 11) << pad("SAH", 9) << pad("C(4.2)", 9)
        << pad("nodes", 12) << pad("leaves", 12) << pad("MB", 9);
    if (first_gpu) out << pad("dev MiB", 9);
    out << pad("ours/embree-M", 15) << '\n';
    std::map<std::string, bool> shown;
    for (const BenchRecord& r : records) {
        const std::string label = row_label(r);
        if (shown[label]) continue;
        shown[label] = true;
        const PeerFigures* medium = peer(r, EmbreeQuality::Medium);
        out << pad(label, label_width, true) << pad(format("%.1f", r.build_ms), 10)
            << pad(format("%.1f", r.layout_ms), 11) << pad(format("%.2f", r.stats.sah_cost), 9)
            << pad(format("%.2f", r.stats.quality_cost), 9) << pad(thousands(r.stats.node_count), 12)
            << pad(thousands(r.stats.leaf_count), 12) << pad(format("%.2f", double(r.stats.bytes) / 1e6), 9);
        if (first_gpu)
            out << pad(r.is_gpu() ? format("%.1f", double(r.device_bytes) / (1024.0 * 1024.0)) : "-", 9);
        out << pad(medium && medium->build_ms > 0 ? format("%.2f", r.build_ms / medium->build_ms) : "-", 15) << '\n';
    }
    if (first_cpu) {
        for (const PeerFigures& f : first_cpu->embree) {
            out << pad(std::string("embree/") + embree_quality_name(f.quality), label_width, true)
                << pad(format("%.1f", f.build_ms), 10) << pad("-", 11) << pad("-", 9) << pad("-", 9) << pad("-", 12)
                << pad("-", 12) << pad(f.bytes ? format("%.2f", double(f.bytes) / 1e6) : "-", 9);
            if (first_gpu) out << pad("-", 9);
            out << '\n';
        }
    }

    // Where the GPU rows' structures were built, with the device's stages.
    std::map<std::string, bool> described;
    for (const BenchRecord& r : records) {
        if (!r.is_gpu() || described[row_label(r)]) continue;
        described[row_label(r)] = true;
        out << "  " << row_label(r) << ": " << format_device_build(r.device_build) << '\n';
    }
    print_kernel_resources(out, records);

    // Traces: Mrays/s; Embree columns and ratios when the peer ran; the
    // agreement of CPU rows with Embree medium, of GPU rows with the CPU reference.
    const std::vector<PeerFigures> no_peers;
    const std::vector<PeerFigures>& peer_columns = first_cpu ? first_cpu->embree : no_peers;
    out << '\n' << pad("trace", 15, true) << pad("res", 10, true) << pad("structure", label_width, true)
        << pad("rays", 12) << pad("Mrays/s", 9);
    for (const PeerFigures& f : peer_columns) out << pad(std::string("E-") + embree_quality_name(f.quality), 9);
    for (const PeerFigures& f : peer_columns) out << pad(std::string("/E-") + embree_quality_name(f.quality), 10);
    const bool agreement_columns = has_peer || first_gpu;
    if (agreement_columns) out << pad(first_gpu ? "agree" : "agree(M)", 10) << pad(first_gpu ? "max dt" : "max dt(M)", 10);
    out << pad("nodes/ray", 10) << pad("fetches/ray", 12) << pad("tris/ray", 9) << '\n';
    for (const BenchRecord& r : records) {
        const std::string res = std::to_string(r.width) + "x" + std::to_string(r.height) +
                                (r.view ? "/v" + std::to_string(r.view) : "");
        out << pad(ray_set_name(r.ray_set), 15, true) << pad(res, 10, true) << pad(row_label(r), label_width, true)
            << pad(thousands(r.rays), 12) << pad(format("%.2f", r.mrays_per_s), 9);
        for (size_t p = 0; p < peer_columns.size(); ++p)
            out << pad(p < r.embree.size() ? format("%.2f", r.embree[p].mrays_per_s) : "-", 9);
        for (size_t p = 0; p < peer_columns.size(); ++p)
            out << pad(p < r.embree.size() && r.embree[p].mrays_per_s > 0
                           ? format("%.2f", r.mrays_per_s / r.embree[p].mrays_per_s)
                           : "-",
                       10);
        if (agreement_columns) {
            const PeerFigures* medium = peer(r, EmbreeQuality::Medium);
            const PeerFigures* ref = medium ? medium : r.embree.empty() ? nullptr : &r.embree.front();
            if (r.reference) {
                out << pad(format("%.4f%%", 100.0 * r.reference->agreement), 10)
                    << pad(format("%.1e", r.reference->max_rel_t_diff), 10);
            } else if (ref) {
                out << pad(format("%.4f%%", 100.0 * ref->agreement), 10) << pad(format("%.1e", ref->max_rel_t_diff), 10);
            } else {
                out << pad("-", 10) << pad("-", 10);
            }
        }
        out << pad(r.has_counts ? format("%.1f", r.steps_per_ray) : "-", 10)
            << pad(r.has_counts && r.fetches_per_ray > 0 ? format("%.1f", r.fetches_per_ray) : "-", 12)
            << pad(r.has_counts ? format("%.2f", r.prims_per_ray) : "-", 9) << '\n';
    }
    if (first_gpu) {
        const BenchRecord& g = *first_gpu;
        out << "agree: " << (has_peer ? "cpu rows with embree/medium, " : "") << g.device
            << " rows with the CPU's " << (g.reference ? g.reference->reference : std::string("reference"))
            << " on the same rays (hit/miss and primitive; any-hit sets: the answer)\n";
    }
    out.flush();
}

void print_configuration_table(std::ostream& out, const std::vector<BenchRecord>& records) {
    struct Sums {
        double p = 0, s = 0, r = 0;
        bool has_p = false, has_s = false, has_r = false;
        double steps[3] = {0, 0, 0}, tests[3] = {0, 0, 0};
    };
    std::map<std::string, Sums> rows;
    std::vector<std::string> order;
    for (const BenchRecord& rec : records) {
        const std::string key = rec.scene + " " + std::to_string(rec.width) + "x" + std::to_string(rec.height) +
                                " " + (rec.is_gpu() ? rec.device + " " : "") + rec.candidate.label();
        if (!rows.count(key)) order.push_back(key);
        Sums& s = rows[key];
        const int column = rec.ray_set == RaySetKind::Primary ? 0 : rec.ray_set == RaySetKind::Shadow ? 1
                           : rec.ray_set == RaySetKind::Reflection ? 2 : -1;
        if (column < 0) continue;
        (column == 0 ? s.p : column == 1 ? s.s : s.r) = rec.trace_ms;
        (column == 0 ? s.has_p : column == 1 ? s.has_s : s.has_r) = true;
        s.steps[column] = rec.has_counts ? rec.steps_per_ray : NAN;
        s.tests[column] = rec.has_counts ? rec.prims_per_ray : NAN;
    }
    out << "\nframe times (ms; P = primary, PS = + shadow, PSR = + reflection) and, per newly added ray type, "
           "steps / primitive tests per ray (Zlatuška 2009, tables 5.9-5.11)\n";
    out << pad("scene res structure", 44, true) << pad("P", 9) << pad("PS", 9) << pad("PSR", 9) << pad("steps P", 9)
        << pad("PS", 8) << pad("PSR", 8) << pad("tests P", 9) << pad("PS", 8) << pad("PSR", 8) << '\n';
    for (const std::string& key : order) {
        const Sums& s = rows[key];
        out << pad(key, 44, true) << pad(s.has_p ? format("%.1f", s.p) : "-", 9)
            << pad(s.has_p && s.has_s ? format("%.1f", s.p + s.s) : "-", 9)
            << pad(s.has_p && s.has_s && s.has_r ? format("%.1f", s.p + s.s + s.r) : "-", 9);
        for (int c = 0; c < 3; ++c) out << pad(format("%.1f", s.steps[c]), c == 0 ? 9 : 8);
        for (int c = 0; c < 3; ++c) out << pad(format("%.2f", s.tests[c]), c == 0 ? 9 : 8);
        out << '\n';
    }
    out.flush();
}

void write_json(const std::string& path, const std::vector<BenchRecord>& records, const RunInfo& info) {
    const MachineInfo machine = machine_info();
    Json root;
    root["tool"] = "rayforge bench";
    root["rayforge_version"] = RAYFORGE_VERSION;
    root["date"] = iso_date_utc();
    root["command"] = info.command;
    root["preset"] = info.preset.empty() ? Json(nullptr) : Json(info.preset);
    const std::string gpu = info.gpu.empty() ? machine.gpu : info.gpu;
    root["machine"] = {{"cpu", machine.cpu}, {"cores", machine.cores}, {"gpu", gpu.empty() ? Json(nullptr) : Json(gpu)}};
    root["devices"] = info.devices;
    root["threads"] = info.threads > 0 ? info.threads : machine.cores;
    root["repetitions"] = info.repetitions;
    root["build_repetitions"] = info.build_repetitions;
    root["embree_version"] = embree_available() ? Json(embree_version()) : Json(nullptr);
    root["not_implemented"] = info.unimplemented;
    root["notes"] = info.notes;
    Json list = Json::array();
    for (const BenchRecord& r : records) {
        Json rec;
        rec["scene"] = r.scene;
        rec["triangles"] = r.triangles;
        rec["load_ms"] = r.load_ms;
        rec["view"] = r.view;
        rec["width"] = r.width;
        rec["height"] = r.height;
        rec["device"] = r.device;
        rec["gpu"] = r.gpu.empty() ? Json(nullptr) : Json(r.gpu);
        rec["gpu_kernel"] = r.is_gpu() ? Json(r.candidate.layout) : Json(nullptr);
        rec["structure"] = r.candidate.structure;
        rec["builder"] = r.candidate.builder;
        rec["layout"] = r.candidate.layout;
        rec["ray_set"] = ray_set_name(r.ray_set);
        rec["samples_per_pixel"] = r.samples_per_pixel;
        rec["rays"] = r.rays;
        rec["mrays_per_s"] = r.mrays_per_s;
        rec["trace_ms"] = r.trace_ms;
        rec["trace_ms_runs"] = r.trace_ms_runs;
        rec["build_ms"] = r.build_ms;
        rec["build_ms_runs"] = r.build_ms_runs;
        rec["layout_ms"] = r.layout_ms;
        rec["sah_cost"] = number_or_null(r.stats.sah_cost);
        rec["quality_cost"] = number_or_null(r.stats.quality_cost);
        rec["nodes"] = r.stats.node_count;
        rec["leaves"] = r.stats.leaf_count;
        rec["bytes"] = r.stats.bytes;
        rec["triangle_bytes"] = r.triangle_bytes;
        rec["device_bytes"] = r.is_gpu() ? Json(r.device_bytes) : Json(nullptr);
        rec["nodes_per_ray"] = r.has_counts ? Json(r.steps_per_ray) : Json(nullptr);
        rec["fetches_per_ray"] = r.has_counts && r.fetches_per_ray > 0 ? Json(r.fetches_per_ray) : Json(nullptr);
        rec["prims_per_ray"] = r.has_counts ? Json(r.prims_per_ray) : Json(nullptr);
        rec["restarts_per_ray"] = r.has_counts ? Json(r.restarts_per_ray) : Json(nullptr);
        Json peers = Json::object();
        for (const PeerFigures& f : r.embree) {
            peers[embree_quality_name(f.quality)] = {
                {"mrays_per_s", f.mrays_per_s},
                {"trace_ms", f.trace_ms},
                {"build_ms", f.build_ms},
                {"bytes", f.bytes},
                {"ratio_mrays", f.mrays_per_s > 0 ? Json(r.mrays_per_s / f.mrays_per_s) : Json(nullptr)},
                {"ratio_build", f.build_ms > 0 ? Json(r.build_ms / f.build_ms) : Json(nullptr)},
                {"agreement", f.agreement},
                {"max_rel_t_diff", f.max_rel_t_diff}};
        }
        rec["embree"] = peers;
        if (r.reference)
            rec["reference"] = {{"structure", r.reference->reference},
                                {"agreement", r.reference->agreement},
                                {"max_rel_t_diff", r.reference->max_rel_t_diff}};
        else
            rec["reference"] = nullptr;
        rec["kernel_resources"] = r.is_gpu() ? resources_json(r.kernel_resources) : Json(nullptr);
        if (r.is_gpu() && r.device_build.report.on_device) {
            const BuildReport& b = r.device_build.report;
            Json stages = Json::object();
            for (const auto& [name, ms] : b.device_stages) stages[name] = ms;
            rec["device_build"] = {{"device_ms", b.device_ms},     {"stages_ms", stages},
                                   {"layout_ms", b.layout_ms},     {"upload_ms", b.upload_ms},
                                   {"first_ray_ms", b.first_ray_ms},
                                   {"download_ms", b.download_ms}, {"host_ms", b.host_ms},
                                   {"peak_device_bytes", b.peak_device_bytes}, {"detail", b.detail}};
        } else {
            rec["device_build"] = nullptr;  // CPU rows, and GPU rows built on the host
        }
        list.push_back(rec);
    }
    root["records"] = list;
    std::ofstream out(path);
    if (!out) throw Error(path + ": cannot open for writing");
    out << root.dump(1) << '\n';
    if (!out) throw Error(path + ": write failed");
}

std::string thousands(uint64_t value) {
    std::string digits = std::to_string(value), out;
    for (size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
        out += digits[i];
    }
    return out;
}

}  // namespace rf::bench

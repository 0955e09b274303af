#include "device_build_report.h"

#include <cmath>
#include <cstdio>

namespace rf::bench {

GpuBuildStages describe_device_build(const cuda::DeviceBuildStages& s, size_t nodes, double sah_cost) {
    GpuBuildStages out;
    out.on_device = s.on_device;
    const std::pair<const char*, double> stages[] = {
        {"partial tris", s.partial_triangles_ms}, {"bounds", s.bounds_ms},   {"morton", s.morton_ms},
        {"cell pairs", s.cell_pairs_ms},          {"sort", s.sort_ms},       {"clusters", s.clusters_ms},
        {"grid0", s.grid0_ms},                    {"coarse levels", s.coarse_levels_ms},
        {"inner nodes", s.inner_nodes_ms},        {"bottom", s.bottom_ms},   {"top", s.top_ms},
        {"ploc", s.ploc_ms},                      {"hierarchy", s.hierarchy_ms},
        {"leaves", s.leaf_finish_ms},             {"cell ranges", s.cell_ranges_ms},
        {"proximity", s.proximity_ms},            {"boxes", s.boxes_ms},     {"emission", s.device_emit_ms}};
    for (const auto& [name, ms] : stages)
        if (ms > 0.0) out.device_stages.emplace_back(name, ms);
    out.device_ms = s.device_total_ms();
    out.layout_ms = s.layout_ms;
    out.upload_ms = s.upload_ms;
    out.download_ms = s.download_ms;
    out.host_ms = s.emit_ms + s.optimize_ms;
    out.peak_device_bytes = s.peak_device_bytes;
    out.nodes = nodes;
    out.sah_cost = sah_cost;
    std::string detail;
    const auto add = [&](const std::string& text) { detail += (detail.empty() ? "" : ", ") + text; };
    if (s.cluster_count) add(std::to_string(s.cluster_count) + " clusters");
    if (s.bottom_levels) add(std::to_string(s.bottom_levels) + " bottom levels");
    if (s.top_levels) add(std::to_string(s.top_levels) + " top levels");
    if (s.ploc_iterations) add(std::to_string(s.ploc_iterations) + " iterations");
    if (s.references) add(std::to_string(s.references) + " references");
    if (s.occupied_top_cells) add(std::to_string(s.occupied_top_cells) + " top cells");
    out.detail = detail;
    return out;
}

std::string format_device_build(const GpuBuildStages& b) {
    char buffer[256];
    if (!b.on_device) {
        if (b.layout_ms <= 0.0) return "built on the host";
        std::snprintf(buffer, sizeof(buffer), "built on the host, layout converted on the device in %.3f ms",
                      b.layout_ms);
        return buffer;
    }
    std::snprintf(buffer, sizeof(buffer), "device build %.3f ms (", b.device_ms);
    std::string line = buffer;
    for (size_t i = 0; i < b.device_stages.size(); ++i) {
        std::snprintf(buffer, sizeof(buffer), "%s%s %.3f", i ? ", " : "", b.device_stages[i].first.c_str(),
                      b.device_stages[i].second);
        line += buffer;
    }
    line += ")";
    if (b.layout_ms > 0.0) {
        std::snprintf(buffer, sizeof(buffer), " + layout %.3f ms", b.layout_ms);
        line += buffer;
    }
    std::snprintf(buffer, sizeof(buffer), "; peak %.2f MiB on the device; %zu nodes", double(b.peak_device_bytes) / (1024.0 * 1024.0), b.nodes);
    line += buffer;
    if (std::isfinite(b.sah_cost)) {
        std::snprintf(buffer, sizeof(buffer), ", SAH %.2f", b.sah_cost);
        line += buffer;
    }
    if (!b.detail.empty()) line += ", " + b.detail;
    std::snprintf(buffer, sizeof(buffer), "; upload %.2f, download %.2f, host %.2f ms", b.upload_ms, b.download_ms,
                  b.host_ms);
    return line + buffer;
}

}  // namespace rf::bench

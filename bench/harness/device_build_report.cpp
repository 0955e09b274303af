#include "device_build_report.h"

#include <cmath>
#include <cstdio>

namespace rf::bench {

std::string format_device_build(const DeviceBuildSummary& summary) {
    const BuildReport& b = summary.report;
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
    if (b.first_ray_ms > 0.0) {  // a tracer's device build: triangles on the device to the first ray
        std::snprintf(buffer, sizeof(buffer), "; first ray after %.3f ms", b.first_ray_ms);
        line += buffer;
    }
    std::snprintf(buffer, sizeof(buffer), "; peak %.2f MiB on the device; %zu nodes", double(b.peak_device_bytes) / (1024.0 * 1024.0), summary.nodes);
    line += buffer;
    if (std::isfinite(summary.sah_cost)) {
        std::snprintf(buffer, sizeof(buffer), ", SAH %.2f", summary.sah_cost);
        line += buffer;
    }
    if (!b.detail.empty()) line += ", " + b.detail;
    std::snprintf(buffer, sizeof(buffer), "; upload %.2f, download %.2f, host %.2f ms", b.upload_ms, b.download_ms,
                  b.host_ms);
    return line + buffer;
}

}  // namespace rf::bench

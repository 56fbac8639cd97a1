#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace densemap::bench {

/// How much last-level cache each vCPU gets now. On a shared VM the host's other guests take
/// part of it, and a vCPU's share changes by the minute: a pointer chase can take several
/// times longer a step on one vCPU than on the other for minutes at a time, and a lane bound
/// to that vCPU runs slower for it. The bench probes before and after its
/// lanes so that a run's figures carry the machine's state with them, as CPU steal does.
///
/// The ns a step of a dependent pointer chase over `bytes` (one pointer per 64-byte line, in a
/// random cycle) on a thread bound to `cpu`, `steps` steps after one lap to warm up; nullopt
/// when the thread cannot be started or bound there, the buffer cannot be had, or `bytes` holds
/// fewer than two lines.
[[nodiscard]] std::optional<double> chaseNsPerStep(std::size_t bytes, unsigned cpu,
                                                   std::size_t steps);

/// chaseNsPerStep on each of the first `cpus` vCPUs in turn (negative where it failed).
[[nodiscard]] std::vector<double> probeCaches(std::size_t bytes, unsigned cpus, std::size_t steps);

/// "cache probe before the lanes (4 MiB pointer chase, ns a step): vCPU 0 17.3, vCPU 1 104.0".
[[nodiscard]] std::string formatCacheProbe(const char* when, std::size_t bytes,
                                           const std::vector<double>& ns);

}  // namespace densemap::bench

#include "cache_probe.hpp"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <numeric>
#include <random>
#include <system_error>
#include <thread>

namespace densemap::bench {
namespace {

constexpr std::size_t kLine = 64;

/// A random cycle through `lines` lines: next[i * stride] is the index of the line after i.
std::vector<std::uint32_t> randomCycle(std::size_t lines) {
  constexpr std::size_t kStride = kLine / sizeof(std::uint32_t);
  std::vector<std::uint32_t> order(lines);
  std::iota(order.begin(), order.end(), 0U);
  std::mt19937 rng(7);
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<std::uint32_t> next(lines * kStride);
  for (std::size_t k = 0; k < lines; ++k) {
    next[order[k] * kStride] = order[(k + 1) % lines] * static_cast<std::uint32_t>(kStride);
  }
  return next;
}

}  // namespace

std::optional<double> chaseNsPerStep(std::size_t bytes, unsigned cpu, std::size_t steps) {
  const std::size_t lines = bytes / kLine;
  if (lines < 2 || lines > (std::size_t{1} << 26)) return std::nullopt;  // at most 4 GiB
  std::optional<double> ns;
  // A throw inside the thread would end the process (std::terminate), one from starting it would
  // end the run: a probe that cannot run is reported as such instead.
  const auto chase = [&] {
    cpu_set_t set;
    CPU_ZERO(&set);
    if (cpu >= CPU_SETSIZE) return;
    CPU_SET(cpu, &set);
    if (pthread_setaffinity_np(pthread_self(), sizeof(set), &set) != 0) return;
    const std::vector<std::uint32_t> next = randomCycle(lines);  // written on this vCPU
    std::uint32_t at = 0;
    for (std::size_t k = 0; k < lines; ++k) at = next[at];  // one lap: the cache as warm as it gets
    const auto t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < steps; ++k) at = next[at];
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    volatile std::uint32_t end = at;  // the chase's result is used: it cannot be left out
    (void)end;
    ns = s * 1e9 / static_cast<double>(std::max<std::size_t>(steps, 1));
  };
  try {
    std::thread probe([&] {
      try {
        chase();
      } catch (...) {
        ns.reset();  // e.g. std::bad_alloc for the cycle
      }
    });
    probe.join();
  } catch (const std::system_error&) {
    return std::nullopt;  // no thread to bind
  }
  return ns;
}

std::vector<double> probeCaches(std::size_t bytes, unsigned cpus, std::size_t steps) {
  std::vector<double> ns;
  for (unsigned cpu = 0; cpu < cpus; ++cpu) {
    ns.push_back(chaseNsPerStep(bytes, cpu, steps).value_or(-1.0));
  }
  return ns;
}

std::string formatCacheProbe(const char* when, std::size_t bytes, const std::vector<double>& ns) {
  char line[96];
  std::snprintf(line, sizeof(line), "cache probe %s (%g MiB pointer chase, ns a step):", when,
                static_cast<double>(bytes) / 1048576.0);
  std::string out = line;
  for (std::size_t cpu = 0; cpu < ns.size(); ++cpu) {
    if (ns[cpu] < 0) {
      std::snprintf(line, sizeof(line), "%s vCPU %zu -", cpu == 0 ? "" : ",", cpu);
    } else {
      std::snprintf(line, sizeof(line), "%s vCPU %zu %.1f", cpu == 0 ? "" : ",", cpu, ns[cpu]);
    }
    out += line;
  }
  return out;
}

}  // namespace densemap::bench

// densemap: the client CLI of densemap-server (replay, query, snapshot, status, commands) and an
// offline map renderer. Rooms: replay_command, query_command, map_commands (snapshot, save,
// status, reset, clear-bbox; render), load_command; here: the global options and the dispatch.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>

#include "cli_support.hpp"
#include "densemap/cli/allocator.hpp"
#include "densemap/cli/guarded_main.hpp"
#include "densemap/client/client.hpp"
#include "load_command.hpp"
#include "map_commands.hpp"
#include "query_command.hpp"
#include "replay_command.hpp"

namespace densemap::cli {
namespace {

/// --pki DIR --role R fills the six files; an explicit file flag replaces its one. Without any
/// of them: no DDS Security.
Expected<std::optional<dds::SecurityFiles>> securityOptions(
    const std::string& pki_dir, const std::string& role, const dds::SecurityFiles& explicit_files) {
  if (!pki_dir.empty() && role.empty()) return makeError("--pki needs --role");
  if (pki_dir.empty() && !role.empty()) return makeError("--role needs --pki");
  dds::SecurityFiles files =
      pki_dir.empty() ? dds::SecurityFiles{} : dds::SecurityFiles::fromPkiDir(pki_dir, role);
  bool any = !pki_dir.empty();
  for (const dds::SecurityFileField& f : dds::kSecurityFileFields) {
    const std::string& given = explicit_files.*f.member;
    if (given.empty()) continue;
    files.*f.member = given;
    any = true;
  }
  if (!any) return std::optional<dds::SecurityFiles>();
  if (auto ok = dds::checkSecurityFiles(files); !ok) return std::unexpected(ok.error());
  return std::optional<dds::SecurityFiles>(files);
}

}  // namespace
}  // namespace densemap::cli

static int runMain(int argc, char** argv) {
  using namespace densemap;
  CLI::App app{"densemap: client of densemap-server (DDS, loopback by default)"};
  app.require_subcommand(1);
  ClientOptions o;
  int timeout_ms = 5000;
  app.add_option("--domain-id", o.domain_id, "DDS domain id")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  auto* interface_option =
      app.add_option("--interface", o.network_interface, "Network interface for DDS")
          ->capture_default_str();
  app.add_option("--timeout-ms", timeout_ms, "Request timeout")
      ->check(CLI::Range(1, 3'600'000))
      ->capture_default_str();
  app.add_option("--instance", o.instance,
                 "The server to ask among replicas on the domain (its dds.instance)");
  app.add_option("--replicas", o.replicas,
                 "Replicas to fail over to, in order, when --instance leaves a request "
                 "unanswered (comma-separated instances)")
      ->delimiter(',');
  std::string pki_dir, pki_role;
  dds::SecurityFiles security;
  app.add_option("--pki", pki_dir,
                 "DDS Security: a directory made by scripts/make-pki.sh (with --role)")
      ->group("DDS Security");
  app.add_option("--role", pki_role, "DDS Security: the identity in --pki to use")
      ->check(CLI::IsMember({"robot", "operator", "viewer", "server"}))
      ->group("DDS Security");
  for (const dds::SecurityFileField& f : dds::kSecurityFileFields) {
    app.add_option(dds::securityFlag(f), security.*f.member,
                   "DDS Security file (overrides the one from --pki)")
        ->group("DDS Security");
  }

  cli::ReplayCommand replay(app);
  cli::QueryCommand query(app);
  cli::MapCommands map_commands(app);
  cli::RenderCommand render(app);
  cli::LoadCommand load(app);
  CLI11_PARSE(app, argc, argv);
  o.timeout = std::chrono::milliseconds(timeout_ms);
  if (auto files = cli::securityOptions(pki_dir, pki_role, security); !files) {
    return cli::fail(files.error().message);
  } else {
    o.security = *files;
  }
  // Replay and load send a scan of megabytes each period: its buffers are reused from the heap,
  // not faulted in anew each scan, so that the sender takes less of the cores it may share
  // with the server (before any DDS thread starts).
  if (load.parsed() || replay.parsed()) cli::keepScanBuffersInHeap(std::size_t{32} << 20);
  if (load.parsed()) return load.run(o, interface_option->count() > 0);

  if (render.parsed()) return render.run();
  if (replay.parsed()) return replay.run(o);
  // A malformed request is refused now, not after the discovery timeout.
  if (auto ok = query.parsed() ? query.check() : map_commands.check(); !ok) {
    return cli::fail(ok.error().message);
  }
  auto client = cli::connect(o);
  if (!client) return cli::fail(client.error().message);
  if (query.parsed()) return query.run(**client);
  if (map_commands.parsed()) return map_commands.run(**client);
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap", [&] { return runMain(argc, argv); });
}

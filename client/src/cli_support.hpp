#pragma once

#include <cstdio>
#include <memory>
#include <string>

#include "densemap/client/client.hpp"

namespace densemap::cli {

/// The CLI's one way to fail: the message on stderr, exit status 1.
inline int fail(const std::string& message) {
  std::fprintf(stderr, "densemap: error: %s\n", message.c_str());
  return 1;
}

/// A client that has found its server (or the error saying why not).
inline Expected<std::unique_ptr<Client>> connect(const ClientOptions& o) {
  auto client = Client::create(o);
  if (!client) return client;
  if (auto ok = (*client)->waitForServer(); !ok) return std::unexpected(ok.error());
  return client;
}

}  // namespace densemap::cli

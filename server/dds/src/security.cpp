#include "densemap/dds/security.hpp"

#include <fstream>
#include <utility>

namespace densemap::dds {

SecurityFiles SecurityFiles::fromPkiDir(const std::string& dir, const std::string& role) {
  const std::string d = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  return {d + "ca.pem", d + role + ".pem",    d + role + ".key",
          d + "ca.pem", d + "governance.p7s", d + "permissions.p7s"};
}

Expected<void> checkSecurityFiles(const SecurityFiles& files) {
  const std::pair<const char*, const std::string*> fields[] = {
      {"identity_ca", &files.identity_ca}, {"identity_certificate", &files.identity_certificate},
      {"private_key", &files.private_key}, {"permissions_ca", &files.permissions_ca},
      {"governance", &files.governance},   {"permissions", &files.permissions},
  };
  for (const auto& [name, path] : fields) {
    if (path->empty()) return makeError(std::string("security.") + name + " is not set");
    if (!std::ifstream(*path).good()) {
      return makeError(std::string("security.") + name + ": cannot read '" + *path + "'");
    }
  }
  return {};
}

bool isLoopbackInterface(const std::string& name) {
  return name == "lo" || name == "localhost" || name.rfind("127.", 0) == 0 || name == "::1";
}

}  // namespace densemap::dds

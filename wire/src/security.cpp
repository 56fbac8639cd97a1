#include "densemap/wire/security.hpp"

#include <algorithm>
#include <fstream>

namespace densemap::dds {

SecurityFiles SecurityFiles::fromPkiDir(const std::string& dir, const std::string& role) {
  const std::string d = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  return {d + "ca.pem", d + role + ".pem",    d + role + ".key",
          d + "ca.pem", d + "governance.p7s", d + "permissions.p7s"};
}

Expected<void> checkSecurityFiles(const SecurityFiles& files) {
  for (const SecurityFileField& f : kSecurityFileFields) {
    const std::string& path = files.*f.member;
    if (path.empty()) return makeError(std::string("security.") + f.name + " is not set");
    if (!std::ifstream(path).good()) {
      return makeError(std::string("security.") + f.name + ": cannot read '" + path + "'");
    }
  }
  return {};
}

std::string securityFlag(const SecurityFileField& field) {
  std::string flag = std::string("--") + field.name;
  std::replace(flag.begin(), flag.end(), '_', '-');
  return flag;
}

bool isLoopbackInterface(const std::string& name) {
  return name == "lo" || name == "localhost" || name.rfind("127.", 0) == 0 || name == "::1";
}

}  // namespace densemap::dds

#pragma once

#include <array>
#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap::dds {

/// The six files of DDS Security (OMG DDS Security 1.1) that Cyclone's built-in plugins need:
/// PKI-DH authentication, signed governance and permissions, AES-GCM encryption. Paths are
/// files on this machine; `scripts/make-pki.sh DIR` makes a complete set per role.
struct SecurityFiles {
  std::string identity_ca;           // the CA that signed every participant's certificate (PEM)
  std::string identity_certificate;  // this participant's certificate (PEM)
  std::string private_key;           // its private key (PEM, unencrypted)
  std::string permissions_ca;        // the CA that signed governance and permissions (PEM)
  std::string governance;            // signed governance document (S/MIME)
  std::string permissions;           // signed permissions document with this identity's grant

  /// Every file of make-pki.sh's layout for `role` (robot, operator, viewer or server).
  [[nodiscard]] static SecurityFiles fromPkiDir(const std::string& dir, const std::string& role);
};

/// The six files by name: the config field (`security.<name>`; the CLI flag is `--` + name
/// with '-' for '_') and the Cyclone participant property that takes it.
struct SecurityFileField {
  const char* name;
  const char* property;
  std::string SecurityFiles::*member;
};
inline constexpr std::array<SecurityFileField, 6> kSecurityFileFields{{
    {"identity_ca", "dds.sec.auth.identity_ca", &SecurityFiles::identity_ca},
    {"identity_certificate", "dds.sec.auth.identity_certificate",
     &SecurityFiles::identity_certificate},
    {"private_key", "dds.sec.auth.private_key", &SecurityFiles::private_key},
    {"permissions_ca", "dds.sec.access.permissions_ca", &SecurityFiles::permissions_ca},
    {"governance", "dds.sec.access.governance", &SecurityFiles::governance},
    {"permissions", "dds.sec.access.permissions", &SecurityFiles::permissions},
}};

/// A field's command-line flag: "--identity-ca" for identity_ca.
[[nodiscard]] std::string securityFlag(const SecurityFileField& field);

/// All six set and readable; the error names the first that is not.
[[nodiscard]] Expected<void> checkSecurityFiles(const SecurityFiles& files);

/// Whether a network interface name is loopback ("lo", "localhost", 127.x.y.z, ::1).
[[nodiscard]] bool isLoopbackInterface(const std::string& name);

}  // namespace densemap::dds

#pragma once

#include <expected>
#include <string>

namespace densemap {

/// An error a caller can meet and handle (bad file, bad option, malformed input). Bugs and
/// broken invariants abort instead.
struct Error {
  std::string message;
};

template <class T>
using Expected = std::expected<T, Error>;

[[nodiscard]] inline std::unexpected<Error> makeError(std::string message) {
  return std::unexpected<Error>(Error{std::move(message)});
}

}  // namespace densemap

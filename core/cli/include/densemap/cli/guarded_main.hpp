#pragma once

#include <cstdio>
#include <exception>
#include <string>

namespace densemap::cli {

/// What the exception being handled says of itself (call inside a catch block): its what(),
/// or "unknown exception".
inline std::string currentFailure() {
  try {
    throw;
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "unknown exception";
  }
}

/// Runs a program's body so that no exception reaches `main` (docs/security.md, "outside people are
/// hostile"): whatever escapes is printed as "<program>: error: <reason>" and the exit code is
/// 2, never an abort with a core dump. Expected errors should still be returned by the body;
/// this is the last line for the ones nobody foresaw (std::bad_alloc from a huge input, a
/// library that throws).
template <class Body>
int guardedMain(const char* program, Body&& body) noexcept {
  try {
    return body();
  } catch (...) {
    try {
      std::fprintf(stderr, "%s: error: %s\n", program, currentFailure().c_str());
    } catch (...) {  // no memory even for the message
      std::fprintf(stderr, "%s: error: out of memory\n", program);
    }
  }
  return 2;
}

}  // namespace densemap::cli

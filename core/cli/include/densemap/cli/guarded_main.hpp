#pragma once

#include <cstdio>
#include <exception>

namespace densemap::cli {

/// Runs a program's body so that no exception reaches `main` (DESIGN.md, "outside people are
/// hostile"): whatever escapes is printed as "<program>: error: <reason>" and the exit code is
/// 2, never an abort with a core dump. Expected errors should still be returned by the body;
/// this is the last line for the ones nobody foresaw (std::bad_alloc from a huge input, a
/// library that throws).
template <class Body>
int guardedMain(const char* program, Body&& body) noexcept {
  try {
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", program, e.what());
  } catch (...) {
    std::fprintf(stderr, "%s: error: unknown exception\n", program);
  }
  return 2;
}

}  // namespace densemap::cli

#pragma once

namespace densemap::upsample {

/// The largest query-stage dimension an ILN weights file may have: the query stage keeps its
/// vectors on the stack (iln.cpp), and the loader refuses more (iln_load.cpp).
inline constexpr int kMaxDim = 64;

}  // namespace densemap::upsample

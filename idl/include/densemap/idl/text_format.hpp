#pragma once

#include <google/protobuf/message.h>

#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// Parses protobuf text format (config files, load scenarios) into `message`. On failure the
/// error is the parser's first complaint, "line L, column C: why" (1-based).
[[nodiscard]] Expected<void> parseTextFormat(const std::string& text,
                                             google::protobuf::Message& message);

}  // namespace densemap

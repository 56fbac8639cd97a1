#pragma once

#include <google/protobuf/message.h>

#include <memory>

#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// Parses protobuf text format (config files, load scenarios) into `message`. On failure the
/// error is the parser's first complaint, "line L, column C: why" (1-based).
[[nodiscard]] Expected<void> parseTextFormat(const std::string& text,
                                             google::protobuf::Message& message);

/// Where a parsed text's fields were written, for errors found after parsing (a value out of
/// range): locate("map.max_range_m") is "line L, column C" (1-based) of that field's name, or
/// of the nearest enclosing message the text sets (a field left at its default), or "" when
/// the text sets none of the path.
class TextLocations {
 public:
  TextLocations();
  ~TextLocations();
  TextLocations(TextLocations&&) noexcept;
  TextLocations& operator=(TextLocations&&) noexcept;

  [[nodiscard]] std::string locate(const std::string& path) const;

 private:
  friend Expected<void> parseTextFormat(const std::string&, google::protobuf::Message&,
                                        TextLocations*);
  struct Tree;
  std::unique_ptr<Tree> tree_;
};

/// parseTextFormat that also records where each field was written.
[[nodiscard]] Expected<void> parseTextFormat(const std::string& text,
                                             google::protobuf::Message& message,
                                             TextLocations* locations);

/// `error` prefixed with the location of the field path it starts with ("map.max_range_m must
/// be ..." -> "line 3, column 3: map.max_range_m must be ..."), when `locations` has one.
[[nodiscard]] std::string locatedError(const TextLocations& locations, const std::string& error);

}  // namespace densemap

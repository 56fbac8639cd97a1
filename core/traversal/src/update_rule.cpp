#include "densemap/traversal/update_rule.hpp"

#include <string>

namespace densemap {

std::string_view ruleName(UpdateRule rule) { return rule == UpdateRule::kSet ? "set" : "per_ray"; }

Expected<UpdateRule> parseUpdateRule(std::string_view name) {
  if (name == "set") return UpdateRule::kSet;
  if (name == "per_ray") return UpdateRule::kPerRay;
  return makeError("unknown update rule '" + std::string(name) + "' (expected set or per_ray)");
}

}  // namespace densemap

// The render module's bad-argument error: one line naming the field and the reason.
#pragma once

#include <stdexcept>
#include <string>

namespace flatland::render {

[[noreturn]] inline void fail(const std::string& field, const std::string& reason) {
  throw std::invalid_argument(field + ": " + reason);
}

}  // namespace flatland::render

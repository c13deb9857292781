// How long the longest tests run. The sanitizer stage of scripts/test.sh sets FLATLAND_TEST_SHORT:
// code under AddressSanitizer runs several times slower, and a shorter horizon or fewer repeats of
// the same code paths find the same memory errors. The Release stage always runs the full length,
// which is what the acceptance criteria name.
#pragma once

#include <cstdlib>
#include <string_view>

namespace flatland::test {

inline bool short_tests() {
  const char* env = std::getenv("FLATLAND_TEST_SHORT");
  return env && *env && std::string_view(env) != "0";
}

}  // namespace flatland::test

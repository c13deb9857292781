// Numbers as text, the one way flatland writes them: files and JSON in their shortest round-trip
// form, messages with as many significant digits as a reader needs.
#pragma once

#include <string>

namespace flatland::sim {

/// Shortest text that reads back as exactly v (std::to_chars); "nan", "inf", "-inf" otherwise.
std::string format_number(double v);

/// `digits` significant digits, as std::ostream writes a double with precision(digits) (printf's
/// %.{digits}g): for messages, where a value must be recognisable rather than exact.
std::string format_significant(double v, int digits = 6);

}  // namespace flatland::sim

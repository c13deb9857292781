// The scene loader's reader of YAML mappings (strict keys, typed values, one-line errors naming
// the field), shared by the planar and the spatial scene sections. Internal to scene/.
#pragma once

#include "flatland/scene/scene.hpp"
#include "flatland/sim/simulate.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <string_view>

namespace flatland::scene_detail {

/// what() must stay one line even when the input contains newlines (in keys, values or the path).
inline std::string one_line(std::string s) {
  std::string out;
  out.reserve(s.size());
  for (char ch : s) {
    if (ch == '\n')
      out += "\\n";
    else if (ch == '\r')
      out += "\\r";
    else if (ch == '\t')
      out += ' ';
    else
      out += ch;
  }
  return out;
}

[[noreturn]] inline void fail(const std::string& origin, const std::string& field,
                              const std::string& reason) {
  throw SceneError(one_line(origin + ": " + field + ": " + reason));
}

/// How a node looks to a user, for "expected X, got Y" messages. Long scalars are shortened.
inline std::string describe(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return "an empty value";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Map:
      return "a mapping";
    case YAML::NodeType::Scalar:
      break;
  }
  std::string s = node.Scalar();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return "'" + s + "'";
}

/// YAML 1.2 core-schema float, without the hex/octal forms nobody writes in a scene. Parsed here
/// rather than by yaml-cpp's stringstream conversion, which cannot tell "out of range" from "not a
/// number" and whose result would depend on the stream's locale.
enum class NumberParse { kOk, kNotANumber, kOutOfRange };
inline NumberParse parse_number(const std::string& text, double& out) {
  static const std::set<std::string> kPosInf = {".inf", ".Inf", ".INF", "+.inf", "+.Inf", "+.INF"};
  static const std::set<std::string> kNegInf = {"-.inf", "-.Inf", "-.INF"};
  static const std::set<std::string> kNaN = {".nan", ".NaN", ".NAN"};
  if (kPosInf.count(text)) {
    out = std::numeric_limits<double>::infinity();
    return NumberParse::kOk;
  }
  if (kNegInf.count(text)) {
    out = -std::numeric_limits<double>::infinity();
    return NumberParse::kOk;
  }
  if (kNaN.count(text)) {
    out = std::numeric_limits<double>::quiet_NaN();
    return NumberParse::kOk;
  }
  std::string_view s = text;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);  // from_chars rejects a leading '+'
  // Only digits, sign, point and exponent: keeps from_chars' "inf"/"nan" spellings out.
  if (s.empty() || s.find_first_not_of("0123456789.eE+-") != std::string_view::npos)
    return NumberParse::kNotANumber;
  if (s.find_first_of("0123456789") == std::string_view::npos) return NumberParse::kNotANumber;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  if (ec == std::errc::result_out_of_range) return NumberParse::kOutOfRange;
  if (ec != std::errc() || ptr != s.data() + s.size()) return NumberParse::kNotANumber;
  return NumberParse::kOk;
}

/// A YAML mapping at a field path ("" for the document, "object", ...). It rejects unknown and
/// duplicate keys up front, so a misspelt key is reported as such rather than as a missing one.
class MapReader {
 public:
  MapReader(const YAML::Node& node, std::string path, const std::string& origin,
            std::initializer_list<const char*> allowed)
      : node_(node), path_(std::move(path)), origin_(origin) {
    if (!node_.IsMap())
      fail(origin_, path_.empty() ? "(document)" : path_,
           "expected a mapping of keys, got " + describe(node_));
    std::set<std::string> seen;
    for (const auto& kv : node_) {
      if (!kv.first.IsScalar())
        fail(origin_, path_.empty() ? "(document)" : path_,
             "keys must be plain names, got " + describe(kv.first));
      const std::string& key = kv.first.Scalar();
      if (!seen.insert(key).second) fail(origin_, field(key), "duplicate key");
      if (std::find_if(allowed.begin(), allowed.end(), [&](const char* a) { return key == a; }) ==
          allowed.end()) {
        std::string list;
        for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
        fail(origin_, field(key), "unknown key (allowed: " + list + ")");
      }
    }
  }

  std::string field(const std::string& key) const {
    return path_.empty() ? key : path_ + "." + key;
  }
  [[noreturn]] void fail_at(const std::string& key, const std::string& reason) const {
    fail(origin_, field(key), reason);
  }
  bool has(const char* key) const { return static_cast<bool>(node_[key]); }
  const std::string& origin() const { return origin_; }

  /// Required finite number.
  double number(const char* key) const {
    require(key);
    return to_number(node_[key], field(key));
  }
  double number_or(const char* key, double fallback) const {
    return has(key) ? number(key) : fallback;
  }
  std::optional<double> optional_number(const char* key) const {
    if (!has(key)) return std::nullopt;
    return number(key);
  }
  /// Required number > 0.
  double positive(const char* key) const {
    const double v = number(key);
    if (!(v > 0)) fail_at(key, "must be positive, got " + node_[key].Scalar());
    return v;
  }
  double positive_or(const char* key, double fallback) const {
    return has(key) ? positive(key) : fallback;
  }

  bool boolean_or(const char* key, bool fallback) const {
    if (!has(key)) return fallback;
    const YAML::Node n = node_[key];
    // YAML 1.2 core schema only: yaml-cpp would also take yes/no/on/off, which YAML 1.2 reads as
    // strings and which are easy to write by accident.
    if (n.IsScalar() && n.Tag() != "!") {
      const std::string& s = n.Scalar();
      if (s == "true" || s == "True" || s == "TRUE") return true;
      if (s == "false" || s == "False" || s == "FALSE") return false;
    }
    fail_at(key, "expected true or false, got " + describe(n));
  }

  /// Required plain string (any scalar).
  std::string text(const char* key) const {
    require(key);
    const YAML::Node n = node_[key];
    if (!n.IsScalar()) fail_at(key, "expected a string, got " + describe(n));
    return n.Scalar();
  }
  /// Required string from a fixed set of words.
  std::string choice(const char* key, std::initializer_list<const char*> allowed) const {
    const std::string s = text(key);
    return check_choice(key, s, allowed);
  }
  std::string choice_or(const char* key, std::initializer_list<const char*> allowed,
                        const char* fallback) const {
    return has(key) ? choice(key, allowed) : std::string(fallback);
  }

  /// Optional integer in [lo, hi]. Written as a plain integer: 2.0 or 2.5 are rejected, since a
  /// count or a size with a fraction is a mistake rather than something to round.
  long long integer_or(const char* key, long long lo, long long hi, long long fallback) const {
    if (!has(key)) return fallback;
    const YAML::Node n = node_[key];
    const long long v = to_integer(n, field(key));
    if (v < lo || v > hi)
      fail_at(key, "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                       "], got " + n.Scalar());
    return v;
  }

  /// Optional fixed-length list of finite numbers ("[x, y, z]"); `shape` names the elements for
  /// the error message.
  template <std::size_t N>
  std::array<double, N> numbers_or(const char* key, const char* shape,
                                   const std::array<double, N>& fallback) const {
    if (!has(key)) return fallback;
    const YAML::Node n = node_[key];
    if (!n.IsSequence() || n.size() != N)
      fail_at(key, "expected a list of " + std::to_string(N) + " numbers " + shape + ", got " +
                       (n.IsSequence() ? "a list of " + std::to_string(n.size()) : describe(n)));
    std::array<double, N> v{};
    for (std::size_t i = 0; i < N; ++i)
      v[i] = to_number(n[i], field(key) + "[" + std::to_string(i) + "]");
    return v;
  }

  const YAML::Node node(const char* key) const { return node_[key]; }

  MapReader section(const char* key, std::initializer_list<const char*> allowed) const {
    if (!has(key)) fail_at(key, "missing required section");
    return MapReader(node_[key], field(key), origin_, allowed);
  }
  std::optional<MapReader> optional_section(const char* key,
                                            std::initializer_list<const char*> allowed) const {
    if (!has(key)) return std::nullopt;
    return MapReader(node_[key], field(key), origin_, allowed);
  }

  /// Key present but meaningless in this context (e.g. `radius` for an ellipse).
  void reject_if_present(const char* key, const std::string& why) const {
    if (has(key)) fail_at(key, why);
  }

  double to_number(const YAML::Node& n, const std::string& where) const {
    if (!n.IsScalar()) fail(origin_, where, "expected a number, got " + describe(n));
    // A quoted scalar is a string in YAML, even if it looks like a number.
    if (n.Tag() == "!")
      fail(origin_, where,
           "expected a number, got the string " + describe(n) + " (remove the quotes)");
    double v = 0;
    switch (parse_number(n.Scalar(), v)) {
      case NumberParse::kOk:
        break;
      case NumberParse::kNotANumber:
        fail(origin_, where, "expected a number, got " + describe(n));
      case NumberParse::kOutOfRange:
        fail(origin_, where, "number out of range, got " + describe(n));
    }
    if (!std::isfinite(v)) fail(origin_, where, "must be a finite number, got " + n.Scalar());
    return v;
  }

  /// A plain decimal integer (optional sign); numbers with a fraction or exponent are rejected.
  long long to_integer(const YAML::Node& n, const std::string& where) const {
    if (!n.IsScalar()) fail(origin_, where, "expected an integer, got " + describe(n));
    if (n.Tag() == "!")
      fail(origin_, where,
           "expected an integer, got the string " + describe(n) + " (remove the quotes)");
    std::string_view s = n.Scalar();
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    long long v = 0;
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec == std::errc::result_out_of_range)
      fail(origin_, where, "number out of range, got " + describe(n));
    if (ec != std::errc() || ptr != s.data() + s.size() || s.empty())
      fail(origin_, where, "expected an integer, got " + describe(n));
    return v;
  }

 private:
  void require(const char* key) const {
    if (!has(key)) fail_at(key, "missing required key");
  }
  std::string check_choice(const char* key, const std::string& s,
                           std::initializer_list<const char*> allowed) const {
    std::string list;
    for (const char* a : allowed) {
      if (s == a) return s;
      list += std::string(list.empty() ? "" : ", ") + a;
    }
    fail_at(key, "unknown value '" + s + "' (allowed: " + list + ")");
  }

  YAML::Node node_;
  std::string path_;
  const std::string& origin_;
};

/// The `integrator` section's method and tolerances (planar and spatial scenes alike).
inline void read_integrator_settings(const MapReader& it, sim::IntegratorSettings& s) {
  const std::string m = it.choice_or("method", {"dopri5", "dop853", "rk4"}, "dopri5");
  s.method = m == "rk4"      ? sim::Method::kRungeKutta4
             : m == "dop853" ? sim::Method::kDormandPrince853
                             : sim::Method::kDormandPrince54;
  // Each value within the bounds sim sets for inputs (integrator_setting_problem).
  const auto checked = [&it](const char* key, double fallback) {
    if (!it.has(key)) return fallback;
    const double v = it.number(key);
    const std::string problem = sim::integrator_setting_problem(key, v);
    if (!problem.empty()) it.fail_at(key, problem);
    return v;
  };
  s.rtol = checked("rtol", s.rtol);
  s.atol = checked("atol", s.atol);
  s.fixed_step = checked("step", s.fixed_step);
  s.max_step = checked("max_step", s.max_step);
  if (it.has("energy_tolerance")) s.energy_tolerance = checked("energy_tolerance", 0.0);
  // The step budget: a run that would need more stops (or is refused at once when its rate says
  // so). Recorded runs keep ~0.4 kB per step, so a billion steps is the most that can be asked.
  s.max_steps = static_cast<long>(it.integer_or("max_steps", 1, 1'000'000'000, s.max_steps));
}

}  // namespace flatland::scene_detail

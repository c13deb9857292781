// The fitted world as a scene file: values edited where they stand in the scene's text (its
// comments kept), checked by parsing the result back.
#include "flatland/identify/fitted_scene.hpp"

#include "flatland/sim/format.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace flatland::identify {

namespace {

/// One key the fitted scene sets.
struct Edit {
  SceneKey key;
  std::string value;    ///< as written (shortest round-trip text for numbers)
  std::string comment;  ///< the line's new trailing comment
  bool remove = false;  ///< comment the key out instead (a key the hybrid model refuses)
};

/// The key node `key` of a mapping (its mark is where its line starts).
YAML::Node key_node(const YAML::Node& map, const std::string& key) {
  for (const auto& entry : map)
    if (entry.first.IsScalar() && entry.first.Scalar() == key) return entry.first;
  return YAML::Node();
}

std::string number_text(double v) { return sim::format_number(v); }

/// The text from `pos` to the end of its line, split at a comment: the value's text (trimmed)
/// and whether the layout is the plain `key: value  # comment` of a block mapping.
bool plain_value_span(const std::string& text, std::size_t pos, std::size_t& end) {
  const std::size_t eol = std::min(text.find('\n', pos), text.size());
  std::size_t value_end = eol;
  for (std::size_t i = pos; i < eol; ++i)
    if (text[i] == '#' && i > pos && (text[i - 1] == ' ' || text[i - 1] == '\t')) {
      value_end = i;
      break;
    }
  const std::string value = text.substr(pos, value_end - pos);
  // A flow collection or a quoted or multi-line scalar: not this simple layout.
  if (value.find_first_of(",{}[]\"'|>") != std::string::npos) return false;
  end = eol;
  return true;
}

/// Apply the edits to the text; false if one of them meets a layout it cannot follow.
bool edit_in_place(std::string& text, const std::vector<Edit>& edits) {
  for (const Edit& e : edits) {
    const YAML::Node root = YAML::Load(text);  // marks refer to the text as edited so far
    const YAML::Node section = root[e.key.section];
    const std::string line = e.key.key + ": " + e.value + "  # " + e.comment;
    if (e.remove) {
      if (!section || !section.IsMap() || section.Style() != YAML::EmitterStyle::Block)
        return false;
      const YAML::Node key = key_node(section, e.key.key);
      const YAML::Node value = section[e.key.key];
      if (!key || key.Mark().is_null() || !value || !value.IsScalar()) return false;
      const auto pos = static_cast<std::size_t>(key.Mark().pos);
      std::size_t end = 0;
      if (!plain_value_span(text, static_cast<std::size_t>(value.Mark().pos), end)) return false;
      text.insert(end, "  (" + e.comment + ")");
      text.insert(pos, "# ");
      continue;
    }
    if (!section) {
      if (!text.empty() && text.back() != '\n') text += '\n';
      text += "\n" + e.key.section + ":\n  " + line + "\n";
      continue;
    }
    if (!section.IsMap() || section.Style() != YAML::EmitterStyle::Block) return false;
    const YAML::Node value = section[e.key.key];
    if (value) {
      if (!value.IsScalar() || value.Mark().is_null()) return false;
      const auto pos = static_cast<std::size_t>(value.Mark().pos);
      std::size_t end = 0;
      if (!plain_value_span(text, pos, end)) return false;
      text.replace(pos, end - pos, e.value + "  # " + e.comment);
      continue;
    }
    // A new key: before the section's first key, at its indentation.
    const YAML::Mark first = section.Mark();
    if (first.is_null() || first.column <= 0) return false;
    const auto line_start = static_cast<std::size_t>(first.pos - first.column);
    text.insert(line_start, std::string(static_cast<std::size_t>(first.column), ' ') + line + "\n");
  }
  return true;
}

/// The document written anew with the edits (the scene's comments are lost).
std::string emit_with_edits(const std::string& scene_text, const std::vector<Edit>& edits) {
  YAML::Node root = YAML::Load(scene_text);
  for (const Edit& e : edits) {
    if (e.remove)
      root[e.key.section].remove(e.key.key);
    else
      root[e.key.section][e.key.key] = e.value;
  }
  YAML::Emitter out;
  out << root;
  return std::string(out.c_str()) + "\n";
}

/// Whether `text` parses and carries every edit's value.
bool carries(const std::string& text, const std::vector<Edit>& edits) {
  try {
    const YAML::Node root = YAML::Load(text);
    for (const Edit& e : edits) {
      const YAML::Node v = root[e.key.section][e.key.key];
      if (e.remove ? static_cast<bool>(v) : (!v || !v.IsScalar() || v.Scalar() != e.value))
        return false;
    }
    return true;
  } catch (const YAML::Exception&) {
    return false;
  }
}

std::string sigma_text(const ParameterEstimate& p) {
  return p.sigma ? number_text(p.value) + " +- " + sim::format_significant(*p.sigma, 2)
                 : std::string("not determined");
}

std::string unit_of(const std::string& name) {
  if (name == "rolling_resistance") return " m";
  if (name == "drag") return " N s/m";
  if (name == "drag_angular") return " N m s/rad";
  if (name == "tilt" || name == "angle_offset") return " rad";
  if (name == "time_offset") return " s";
  return "";
}

/// The comment block at the top of the fitted scene.
std::string provenance_block(const IdentifyResult& result, const FitProvenance& provenance) {
  std::ostringstream os;
  os << "# World parameters identified from recordings by `flatland identify` (docs/IDENTIFY.md).\n"
     << "#   from the scene:  " << provenance.scene_path << "\n"
     << "#   command:         " << provenance.command_line << "\n";
  for (const std::string& r : provenance.recordings) os << "#   recording:       " << r << "\n";
  os << "#   fit:             chi^2 = " << sim::format_significant(result.chi2, 6) << " for "
     << result.degrees_of_freedom << " degrees of freedom (chi^2/dof = "
     << (result.degrees_of_freedom > 0
             ? sim::format_significant(result.chi2 / result.degrees_of_freedom, 4)
             : std::string("undefined"))
     << "), " << result.iterations << " iterations, "
     << (result.converged ? "converged" : "NOT converged: " + result.termination) << "\n"
     << "#   contact.model is hybrid: the model the fit simulates.\n";
  for (const std::string& w : result.warnings) os << "#   warning:         " << w << "\n";
  os << "# Parameters (1-sigma; a parameter the data did not determine keeps the scene's value):\n";
  for (const ParameterEstimate& p : result.parameters) {
    const std::optional<SceneKey> key = scene_key(p.name);
    os << "#   " << p.name << ": ";
    if (p.sigma)
      os << number_text(p.value) << " +- " << sim::format_significant(*p.sigma, 2)
         << unit_of(p.name);
    else
      os << "not determined (" << p.not_determined << ")";
    if (key && !p.sigma)
      os << "  (" << key->section << "." << key->key << ": the scene's value kept)";
    else if (key)
      os << "  -> " << key->section << "." << key->key
         << (key->scale != 1.0 ? " (" + number_text(p.value * key->scale) + ")" : "");
    else
      os << "  (not a scene key: " << (p.name == "time_offset" ? "the camera's" : "the joint's")
         << " offset)";
    os << "\n";
  }
  os << "\n";
  return os.str();
}

}  // namespace

std::optional<SceneKey> scene_key(const std::string& parameter) {
  if (parameter == "mu_static") return SceneKey{"contact", "mu"};
  if (parameter == "mu_kinetic") return SceneKey{"contact", "mu_kinetic"};
  if (parameter == "restitution") return SceneKey{"contact", "restitution"};
  if (parameter == "rolling_resistance") return SceneKey{"contact", "rolling_resistance"};
  if (parameter == "drag") return SceneKey{"contact", "drag"};
  if (parameter == "drag_angular") return SceneKey{"contact", "drag_angular"};
  if (parameter == "tilt") return SceneKey{"gravity", "tilt_deg", 180.0 / std::numbers::pi};
  return std::nullopt;
}

std::string fitted_scene(const std::string& scene_text, const IdentifyResult& result,
                         const FitProvenance& provenance) {
  YAML::Node original;
  try {
    original = YAML::Load(scene_text);
  } catch (const YAML::Exception& e) {
    throw std::invalid_argument(provenance.scene_path + ": not YAML: " + e.msg);
  }
  if (!original.IsMap())
    throw std::invalid_argument(provenance.scene_path + ": not a scene (a YAML mapping)");
  std::vector<Edit> edits;
  const YAML::Node model = original["contact"] ? original["contact"]["model"] : YAML::Node();
  if (!model || !model.IsScalar() || model.Scalar() != "hybrid") {
    edits.push_back({{"contact", "model"}, "hybrid", "identified in this model"});
    // A key of the rolling model that the hybrid model refuses.
    if (original["contact"] && original["contact"]["stop_on_contact_loss"])
      edits.push_back({{"contact", "stop_on_contact_loss"},
                       "",
                       "rolling model only: left out for the hybrid model the fit simulates",
                       true});
  }
  for (const ParameterEstimate& p : result.parameters) {
    const std::optional<SceneKey> key = scene_key(p.name);
    if (!key || !p.sigma) continue;
    const YAML::Node old = original[key->section] ? original[key->section][key->key] : YAML::Node();
    const std::string was =
        old && old.IsScalar() ? " (was " + old.Scalar() + ")" : std::string(" (was unset)");
    ParameterEstimate in_scene_units = p;
    in_scene_units.value = p.value * key->scale;
    in_scene_units.sigma = *p.sigma * key->scale;
    edits.push_back({*key, number_text(in_scene_units.value),
                     "identified: " + sigma_text(in_scene_units) + was});
  }
  // mu_kinetic needs mu: a scene without one gets the static coefficient the fit simulated with.
  const auto sets = [&edits](const std::string& key) {
    return std::any_of(edits.begin(), edits.end(), [&key](const Edit& e) {
      return !e.remove && e.key.section == "contact" && e.key.key == key;
    });
  };
  const bool scene_has_mu = original["contact"] && original["contact"]["mu"];
  if (sets("mu_kinetic") && !sets("mu") && !scene_has_mu && result.world.contact.mu)
    edits.push_back({{"contact", "mu"},
                     number_text(*result.world.contact.mu),
                     "the static coefficient the fit simulated with (not identified)"});
  std::string text = scene_text;
  if (!edit_in_place(text, edits) || !carries(text, edits))
    text = emit_with_edits(scene_text, edits);
  if (!carries(text, edits))
    throw std::logic_error("fitted_scene: the written scene does not carry the fitted values");
  return provenance_block(result, provenance) + text;
}

}  // namespace flatland::identify

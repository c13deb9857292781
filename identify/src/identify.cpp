// identify() and validate(): the multiple-shooting fit (docs/IDENTIFY.md, "Method").
#include "flatland/identify/identify.hpp"

#include <stdexcept>

namespace flatland::identify {

IdentifyResult identify(const sim::SimulationSpec&, const std::vector<Recording>&,
                        const IdentifyOptions&) {
  throw std::logic_error("identify: not built yet");
}

PredictionCheck validate(const sim::SimulationSpec&, const Recording&, const ValidateOptions&) {
  throw std::logic_error("identify::validate: not built yet");
}

}  // namespace flatland::identify

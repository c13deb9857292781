#include "flatland/control/choice.hpp"

#include <stdexcept>

namespace flatland::control {

const std::vector<std::string>& controller_types() {
  static const std::vector<std::string> types{"paper", "transverse"};
  return types;
}

std::unique_ptr<Controller> make_controller(const ControllerChoice& choice) {
  if (choice.type == "paper") return std::make_unique<PaperController>(choice.paper);
  if (choice.type == "transverse")
    return std::make_unique<TransverseController>(choice.transverse, choice.paper);
  throw std::invalid_argument(
      unknown_type_message("controller.type", choice.type, controller_types()));
}

const std::vector<std::string>& estimator_types() {
  static const std::vector<std::string> types{"ekf", "ukf"};
  return types;
}

std::unique_ptr<Estimator> make_estimator(const EstimatorChoice& choice,
                                          std::shared_ptr<const sim::RollingProblem> model) {
  if (choice.type == "ekf") return std::make_unique<Ekf>(std::move(model), choice.config);
  if (choice.type == "ukf")
    return std::make_unique<Ukf>(std::move(model), choice.config, choice.ukf);
  throw std::invalid_argument(
      unknown_type_message("estimator.type", choice.type, estimator_types()));
}

std::string unknown_type_message(const std::string& field, const std::string& name,
                                 const std::vector<std::string>& known) {
  std::string list;
  for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
  return field + ": unknown type '" + name + "' (known: " + list + ")";
}

}  // namespace flatland::control

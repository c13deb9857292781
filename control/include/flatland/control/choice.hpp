// The controller and estimator a scene chose by name (`controller.type`, `estimator.type`), each
// with its typed config, and the factories that make a fresh instance of the choice for one run.
#pragma once

#include "flatland/control/controller.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/control/interfaces.hpp"
#include "flatland/control/transverse.hpp"
#include "flatland/control/ukf.hpp"

#include <memory>
#include <string>
#include <vector>

namespace flatland::control {

/// A scene's controller: its type and the config of each built-in type (only the chosen one's is
/// used; `transverse` also runs the paper's dip, finish and hold with `paper`).
struct ControllerChoice {
  std::string type = "paper";
  PaperConfig paper;
  TransverseConfig transverse;
};

/// The built-in controller types, in the order help lists them ("paper", "transverse").
const std::vector<std::string>& controller_types();
/// A fresh controller of the chosen type (not started). std::invalid_argument naming
/// `controller.type` and the known types for an unknown one.
std::unique_ptr<Controller> make_controller(const ControllerChoice& choice);

/// A scene's estimator: its type and its config (`EstimatorConfig` is shared by the built-in
/// filters: model, latency compensation, process noise, history, initial uncertainty), with each
/// type's own (only the chosen one's is used).
struct EstimatorChoice {
  std::string type = "ekf";
  EstimatorConfig config;
  UkfConfig ukf;  ///< type "ukf": the sigma points
};

/// The built-in estimator types ("ekf", "ukf").
const std::vector<std::string>& estimator_types();
/// A fresh estimator of the chosen type on the nominal model. std::invalid_argument naming
/// `estimator.type` and the known types for an unknown one.
std::unique_ptr<Estimator> make_estimator(const EstimatorChoice& choice,
                                          std::shared_ptr<const sim::RollingProblem> model);

/// "controller.type: unknown type 'x' (known: paper, transverse)": the message for an unknown
/// name, from a list of known ones.
std::string unknown_type_message(const std::string& field, const std::string& name,
                                 const std::vector<std::string>& known);

}  // namespace flatland::control

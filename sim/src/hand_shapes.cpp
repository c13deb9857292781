#include "flatland/sim/hand_shapes.hpp"

#include <stdexcept>

namespace flatland::sim {

std::shared_ptr<const PointsHand> make_points_hand(const PointsHandSpec&) {
  throw std::logic_error("hand.shape: points is not built yet");
}

std::vector<Vec2> read_hand_points_csv(const std::string&, double) {
  throw std::logic_error("hand.file: the points reader is not built yet");
}

std::shared_ptr<const PolarHand> make_polar_hand(const PolarHandSpec&) {
  throw std::logic_error("hand.shape: polar is not built yet");
}

}  // namespace flatland::sim

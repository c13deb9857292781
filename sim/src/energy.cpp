#include "flatland/sim/energy.hpp"

#include "flatland/sim/format.hpp"

namespace flatland::sim {

std::string breach_text(const EnergyAudit& a) {
  return "the energy balance broke at t = " + format_significant(a.t_broken, 10) + " s (" +
         format_significant(a.balance, 3) + " J, bound " + format_significant(a.bound(), 3) + " J)";
}

}  // namespace flatland::sim

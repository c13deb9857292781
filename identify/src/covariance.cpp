// The fit's report: residuals per sample, chi^2, and the covariance of the unknowns from the
// Jacobian at the solution, with the refusal of what the data do not determine.
#include "covariance.hpp"

#include "flatland/sim/format.hpp"

#include <ceres/crs_matrix.h>

#include <Eigen/SVD>

#include <boost/math/distributions/chi_squared.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace flatland::identify::detail {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// Singular values of the column-scaled Jacobian below this fraction of the largest are taken
/// as zero: the derivatives' own error (central differences on a run accurate to ~1e-10) is
/// about 1e-6 of a column's size, so a direction that small is not known to be constrained.
constexpr double kNullSingularValue = 1e-6;
/// Beyond this |correlation| a parameter that is not determined is named with its partner.
constexpr double kPartnerCorrelation = 0.9;
/// Within this fraction of the bounds' width a value is at its bound.
constexpr double kAtBound = 1e-9;

bool is_offset(const std::string& name) { return name == "angle_offset" || name == "time_offset"; }

/// The Jacobian at the solution as a dense matrix, columns: the unknowns, then each segment's
/// (s_h, sdot_h); rows: the residual blocks in their order (samples, then continuity).
Eigen::MatrixXd jacobian_at_solution(ceres::Problem& solved, std::vector<double>& w,
                                     std::vector<std::array<double, 2>>& states, int threads,
                                     std::vector<double>& residuals) {
  ceres::Problem::EvaluateOptions eo;
  if (!w.empty()) eo.parameter_blocks.push_back(w.data());
  for (auto& s : states) eo.parameter_blocks.push_back(s.data());
  eo.num_threads = threads;
  double cost = 0;
  ceres::CRSMatrix crs;
  if (!solved.Evaluate(eo, &cost, &residuals, nullptr, &crs))
    throw std::runtime_error("identify: the simulator failed at the solution's differences");
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r)
    for (int i = crs.rows[static_cast<std::size_t>(r)];
         i < crs.rows[static_cast<std::size_t>(r) + 1]; ++i)
      J(r, crs.cols[static_cast<std::size_t>(i)]) = crs.values[static_cast<std::size_t>(i)];
  return J;
}

/// The covariance of all fitted quantities, pseudo-inverse of J^T J over the directions the
/// column-scaled Jacobian resolves; `null_of[j]` lists, per column, the null directions'
/// components (|v| > 0.1) and `insensitive[j]` marks columns the residuals do not depend on.
struct Covariance {
  Eigen::MatrixXd C;
  std::vector<std::vector<int>>
      null_partners;  ///< per column: the columns sharing a null direction
  std::vector<bool> in_null, insensitive;
};

Covariance covariance_of(const Eigen::MatrixXd& J) {
  const Eigen::Index P = J.cols();
  Covariance out;
  out.C = Eigen::MatrixXd::Zero(P, P);
  out.null_partners.assign(static_cast<std::size_t>(P), {});
  out.in_null.assign(static_cast<std::size_t>(P), false);
  out.insensitive.assign(static_cast<std::size_t>(P), false);
  Eigen::VectorXd scale(P);
  const double largest = J.colwise().norm().maxCoeff();
  for (Eigen::Index j = 0; j < P; ++j) {
    scale[j] = J.col(j).norm();
    if (!(scale[j] > 1e-12 * largest)) {
      out.insensitive[static_cast<std::size_t>(j)] = true;
      scale[j] = 1.0;
    }
  }
  Eigen::MatrixXd Js = J * scale.cwiseInverse().asDiagonal();
  for (Eigen::Index j = 0; j < P; ++j)
    if (out.insensitive[static_cast<std::size_t>(j)]) Js.col(j).setZero();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  const Eigen::MatrixXd& V = svd.matrixV();
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    const Eigen::VectorXd v = V.col(i);
    if (sv[i] > kNullSingularValue * sv[0]) {
      out.C += v * v.transpose() / (sv[i] * sv[i]);
      continue;
    }
    std::vector<int> members;
    for (Eigen::Index j = 0; j < P; ++j)
      if (std::abs(v[j]) > 0.1 && !out.insensitive[static_cast<std::size_t>(j)])
        members.push_back(static_cast<int>(j));
    for (int j : members) {
      out.in_null[static_cast<std::size_t>(j)] = true;
      for (int m : members)
        if (m != j) out.null_partners[static_cast<std::size_t>(j)].push_back(m);
    }
  }
  out.C = scale.cwiseInverse().asDiagonal() * out.C * scale.cwiseInverse().asDiagonal();
  return out;
}

/// Why parameter j (a column among the unknowns) is not determined, or "" when it is.
std::string refusal(const Unknown& u, double value, double sigma, std::size_t j,
                    const Covariance& cov, const std::vector<Unknown>& unknowns,
                    double max_relative_sigma, int& partner) {
  partner = -1;
  const auto name_of = [&](int column) {
    return column < static_cast<int>(unknowns.size())
               ? unknowns[static_cast<std::size_t>(column)].name
               : std::string("the segments' initial states");
  };
  if (cov.insensitive[j]) return "the data do not depend on it";
  if (cov.in_null[j]) {
    std::string partners;
    for (int m : cov.null_partners[j]) partners += (partners.empty() ? "" : ", ") + name_of(m);
    return partners.empty() ? "the data do not constrain it"
                            : "the data cannot separate it from " + partners;
  }
  const double width = u.bounds.upper - u.bounds.lower;
  if (value <= u.bounds.lower + kAtBound * width)
    return "at its lower bound " + sim::format_number(u.bounds.lower) + " (no sigma at a bound)";
  if (value >= u.bounds.upper - kAtBound * width)
    return "at its upper bound " + sim::format_number(u.bounds.upper) + " (no sigma at a bound)";
  // Offsets may be 0: compared with a tenth of their range; the others with their value.
  const double reference = is_offset(u.name) ? 0.1 * width : std::abs(value);
  if (sigma <= max_relative_sigma * reference) return "";
  std::string why = "sigma " + sim::format_significant(sigma, 2) + " exceeds " +
                    sim::format_number(max_relative_sigma) +
                    (is_offset(u.name) ? " x a tenth of its range" : " x its value");
  // The unknown it is most correlated with, when that explains it.
  double best = 0;
  for (std::size_t m = 0; m < unknowns.size(); ++m) {
    if (m == j) continue;
    const double c = cov.C(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(m)) /
                     std::sqrt(cov.C(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(j)) *
                               cov.C(static_cast<Eigen::Index>(m), static_cast<Eigen::Index>(m)));
    if (std::abs(c) > std::abs(best)) best = c, partner = static_cast<int>(m);
  }
  if (partner >= 0 && std::abs(best) > kPartnerCorrelation)
    why += ": the data cannot separate it from " + name_of(partner) + " (correlation " +
           sim::format_significant(best, 3) + ")";
  else
    partner = -1;
  return why;
}

/// chi^2 against its degrees of freedom: the 99 % quantile and, beyond it, the Birge ratio
/// sqrt(chi^2 / dof) by which every sigma is scaled (1 when chi^2 is consistent).
void consistency(IdentifyResult& result) {
  result.sigma_scale = 1;
  if (result.degrees_of_freedom <= 0) {
    result.chi2_limit = std::numeric_limits<double>::infinity();
    return;
  }
  result.chi2_limit = boost::math::quantile(boost::math::chi_squared(result.degrees_of_freedom),
                                            kConsistentChi2Quantile);
  if (result.chi2 > result.chi2_limit)
    result.sigma_scale = std::sqrt(result.chi2 / result.degrees_of_freedom);
}

}  // namespace

void report_fit(const ShootingProblem& problem, ceres::Problem& solved, std::vector<double>& w,
                std::vector<std::array<double, 2>>& states, const IdentifyOptions& options,
                const std::vector<std::string>& held, IdentifyResult& result) {
  std::vector<double> residuals;
  const Eigen::MatrixXd J =
      jacobian_at_solution(solved, w, states, options.threads > 0 ? options.threads : 1, residuals);
  const std::vector<Unknown>& unknowns = problem.unknowns();
  const std::size_t K = unknowns.size();
  std::size_t held_count = 0;
  for (const std::string& why : held) held_count += !why.empty();

  // Per sample, per recording.
  result.fits.clear();
  for (const Recording& r : problem.recordings()) {
    RecordingFit f;
    f.name = r.name;
    result.fits.push_back(f);
  }
  std::size_t row = 0;
  int samples = 0;
  result.chi2 = 0;
  for (std::size_t k = 0; k < problem.segments().size(); ++k) {
    const Segment& seg = problem.segments()[k];
    const Recording& rec = problem.recordings()[seg.recording];
    RecordingFit& f = result.fits[seg.recording];
    for (std::size_t i = seg.first; i < seg.end; ++i, ++row, ++samples) {
      const double z = residuals[row];
      f.t.push_back(rec.t[i]);
      f.measured.push_back(rec.s_h[i]);
      f.fitted.push_back(rec.s_h[i] + z * rec.sigma[i]);
      f.normalised_residual.push_back(z);
      result.chi2 += z * z;
    }
    if (seg.has_next) row += 2;
  }
  result.degrees_of_freedom = samples - static_cast<int>(K - held_count) -
                              2 * static_cast<int>(problem.recordings().size());
  consistency(result);

  // The covariance with the sigma that cover the error: scaled when chi^2 says the weights were
  // too large. The refusals below judge the scaled sigma.
  Covariance cov = covariance_of(J);
  // The Gauss-Newton step at the solution, -(J^T J)^+ J^T r over the directions the data resolve:
  // zero at a minimum; what it would still gain says whether the solver stopped short of one.
  const Eigen::VectorXd gradient =
      J.transpose() * Eigen::Map<const Eigen::VectorXd>(
                          residuals.data(), static_cast<Eigen::Index>(residuals.size()));
  const Eigen::VectorXd step = -cov.C * gradient;
  result.chi2_decrease_expected = -gradient.dot(step);
  const double scale2 = result.sigma_scale * result.sigma_scale;
  cov.C *= scale2;
  result.segments.clear();
  for (std::size_t k = 0; k < problem.segments().size(); ++k) {
    const Segment& seg = problem.segments()[k];
    SegmentState s;
    s.recording = seg.recording;
    s.t0 = seg.t0;
    s.t1 = seg.t_end;
    s.s_h = states[k][0];
    s.sdot_h = states[k][1];
    const auto col = static_cast<Eigen::Index>(K + 2 * k);
    if (!cov.in_null[static_cast<std::size_t>(col)]) s.sigma_s_h = std::sqrt(cov.C(col, col));
    if (!cov.in_null[static_cast<std::size_t>(col) + 1])
      s.sigma_sdot_h = std::sqrt(cov.C(col + 1, col + 1));
    result.segments.push_back(s);
  }

  result.parameters.clear();
  std::vector<bool> determined(K, false);
  std::vector<std::pair<std::size_t, int>> partners;  // (refused, the partner it names or -1)
  for (std::size_t j = 0; j < K; ++j) {
    ParameterEstimate e;
    e.name = unknowns[j].name;
    e.initial = unknowns[j].initial;
    e.value = w[j];
    e.bounds = unknowns[j].bounds;
    e.step_to_minimum = step[static_cast<Eigen::Index>(j)];
    if (j < held.size() && !held[j].empty()) {
      e.not_determined = held[j];
      e.held = true;
      result.parameters.push_back(e);
      continue;
    }
    const double sigma =
        std::sqrt(cov.C(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(j)));
    int partner = -1;
    e.not_determined =
        refusal(unknowns[j], e.value, sigma, j, cov, unknowns, options.max_relative_sigma, partner);
    if (e.not_determined.empty()) {
      e.sigma = sigma;
      e.sigma_unscaled = sigma / result.sigma_scale;
      determined[j] = true;
    }
    result.parameters.push_back(e);
    partners.emplace_back(j, partner);
  }
  // The data constrain a pair only through a combination: its partner is refused too, though its
  // own sigma may pass (it is the one of the two the combination leans on less).
  for (const auto& [j, m] : partners) {
    if (m < 0 || !determined[static_cast<std::size_t>(m)]) continue;
    ParameterEstimate& e = result.parameters[static_cast<std::size_t>(m)];
    const auto jj = static_cast<Eigen::Index>(j), mm = static_cast<Eigen::Index>(m);
    e.not_determined =
        "the data cannot separate it from " + unknowns[j].name + " (correlation " +
        sim::format_significant(cov.C(jj, mm) / std::sqrt(cov.C(jj, jj) * cov.C(mm, mm)), 3) + ")";
    e.sigma.reset();
    e.sigma_unscaled.reset();
    determined[static_cast<std::size_t>(m)] = false;
  }
  result.step_in_sigma = 0;
  for (const ParameterEstimate& e : result.parameters)
    if (e.sigma)
      result.step_in_sigma = std::max(result.step_in_sigma, std::abs(e.step_to_minimum) / *e.sigma);
  result.correlation =
      Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(K), static_cast<Eigen::Index>(K), kNaN);
  for (std::size_t i = 0; i < K; ++i)
    for (std::size_t j = 0; j < K; ++j)
      if (determined[i] && determined[j])
        result.correlation(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
            cov.C(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) /
            (*result.parameters[i].sigma * *result.parameters[j].sigma);
}

}  // namespace flatland::identify::detail

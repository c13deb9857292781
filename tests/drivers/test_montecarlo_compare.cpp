// Comparing controllers on the same worlds (drivers::compare_controllers and its statistics):
// the paired counts against a brute-force count over the records, the exact McNemar p-value
// against the binomial tail summed in exact integer arithmetic and against closed forms, the
// quantiles against order statistics of a sorted array, and the reports' counts and margins
// against a direct pass over the records. The records are made up here (no experiment runs), so
// every case, including numerical failures and safe stops of each cause, is covered.
#include "flatland/drivers/montecarlo.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

using namespace flatland;
using drivers::Outcome;

namespace {

/// P[X <= k] for X ~ Binomial(n, 1/2), n <= 62, summed over exact binomial coefficients.
double binomial_half_cdf(int n, int k) {
  std::uint64_t sum = 0, coefficient = 1;  // C(n, 0)
  for (int i = 0; i <= k; ++i) {
    sum += coefficient;
    coefficient =
        coefficient * static_cast<std::uint64_t>(n - i) / static_cast<std::uint64_t>(i + 1);
  }
  return std::ldexp(static_cast<double>(sum), -n);
}

/// A made-up result: `worlds` worlds under `names`, outcomes drawn from a fixed generator (some
/// numerical failures, safe stops of several causes, successes with margins).
drivers::MonteCarloResult made_up_result(const std::vector<std::string>& names, int worlds,
                                         std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const auto unit = [&] { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  const Outcome outcomes[] = {
      Outcome::kSuccess,  Outcome::kSuccess,     Outcome::kSuccess,
      Outcome::kDropped,  Outcome::kSlidOff,     Outcome::kWrongWell,
      Outcome::kSafeStop, Outcome::kNotFinished, Outcome::kNumericalFailure};
  const control::StopCause causes[] = {control::StopCause::kCamera, control::StopCause::kDisk,
                                       control::StopCause::kTimeout};
  drivers::MonteCarloResult r;
  r.runs = worlds;
  for (const std::string& n : names) r.summaries.push_back({n, 0, 0, {}});
  for (int w = 0; w < worlds; ++w)
    for (const std::string& n : names) {
      drivers::RunRecord rec;
      rec.run = w;
      rec.controller = n;
      rec.outcome = outcomes[rng() % std::size(outcomes)];
      rec.success = rec.outcome == Outcome::kSuccess;
      if (rec.outcome == Outcome::kSafeStop && rng() % 4 != 0)  // some without a cause
        rec.stop_cause = causes[rng() % std::size(causes)];
      rec.duration_s = 3.5 + 2 * unit();
      rec.fn_min_ratio = 0.1 + 0.3 * unit();
      rec.mu = 0.8 * (0.8 + 0.4 * unit());
      rec.mu_max = rec.mu * unit();
      r.records.push_back(rec);
    }
  return r;
}

}  // namespace

TEST(MonteCarloQuantile, MatchesOrderStatisticsOfTheSortedValues) {
  // 21 values in a shuffled order: q = i / 20 lands exactly on the i-th smallest.
  std::vector<double> v;
  for (int i = 0; i <= 20; ++i) v.push_back(std::pow(1.3, i) - 7);
  std::vector<double> shuffled = v;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(3));
  for (int i = 0; i <= 20; ++i) EXPECT_EQ(drivers::quantile(shuffled, i / 20.0), v[i]) << i;
  // Between order statistics: linear, as numpy.percentile([1..10], 5) = 1.45 and the median of
  // four values is the mean of the middle two.
  EXPECT_NEAR(drivers::quantile({10, 9, 8, 7, 6, 5, 4, 3, 2, 1}, 0.05), 1.45, 1e-12);
  EXPECT_EQ(drivers::quantile({4, 1, 3, 2}, 0.5), 2.5);
  EXPECT_NEAR(drivers::quantile({0, 10}, 0.95), 9.5, 1e-12);
  EXPECT_EQ(drivers::quantile({7}, 0.05), 7);
  EXPECT_TRUE(std::isnan(drivers::quantile({}, 0.5)));
  EXPECT_THROW(drivers::quantile({1, 2}, 1.5), std::invalid_argument);
  EXPECT_THROW(drivers::quantile({1, NAN}, 0.5), std::invalid_argument);

  // spread(): the same quantiles of a random sample, against its sorted copy.
  std::mt19937_64 rng(11);
  std::vector<double> sample;
  for (int i = 0; i < 101; ++i) sample.push_back(static_cast<double>(rng() % 1000) / 7);
  std::vector<double> sorted = sample;
  std::sort(sorted.begin(), sorted.end());
  const drivers::Spread s = drivers::spread(sample);
  EXPECT_EQ(s.n, 101);
  EXPECT_EQ(s.min, sorted.front());
  EXPECT_EQ(s.max, sorted.back());
  EXPECT_EQ(s.median, sorted[50]);
  EXPECT_EQ(s.p05, sorted[5]);  // h = 100 * 0.05 = 5
  EXPECT_EQ(s.p95, sorted[95]);
  const drivers::Spread none = drivers::spread({});
  EXPECT_EQ(none.n, 0);
  EXPECT_TRUE(std::isnan(none.median) && std::isnan(none.min) && std::isnan(none.max));
}

TEST(MonteCarloMcNemar, MatchesTheExactBinomialTail) {
  // Closed forms: all five discordant worlds one way: 2 * 0.5^5; one of six the other way:
  // 2 * (1 + 6) / 2^6.
  EXPECT_NEAR(drivers::mcnemar_exact_p(0, 5), 2 * std::pow(0.5, 5), 1e-15);
  EXPECT_NEAR(drivers::mcnemar_exact_p(5, 0), 2 * std::pow(0.5, 5), 1e-15);
  EXPECT_NEAR(drivers::mcnemar_exact_p(1, 5), 14.0 / 64, 1e-15);
  EXPECT_NEAR(drivers::mcnemar_exact_p(0, 49), 2 * std::pow(0.5, 49), 1e-28);
  // No discordant world, or as many each way: no evidence of a difference.
  EXPECT_EQ(drivers::mcnemar_exact_p(0, 0), 1.0);
  EXPECT_EQ(drivers::mcnemar_exact_p(3, 3), 1.0);
  EXPECT_EQ(drivers::mcnemar_exact_p(1, 2), 1.0);  // 2 * (1 + 3) / 8 > 1
  // Every split up to 60 discordant worlds, against the tail summed in integers.
  for (int n = 1; n <= 60; ++n)
    for (int b = 0; b <= n; ++b) {
      const double tail = binomial_half_cdf(n, std::min(b, n - b));
      const double p = std::min(1.0, 2 * tail);
      EXPECT_NEAR(drivers::mcnemar_exact_p(b, n - b), p, 1e-12 * p) << b << " vs " << n - b;
    }
  // Beyond the integers' reach: symmetric, in (0, 1], and monotone in the imbalance (from 250
  // of 2000 on: below that the tail is under the smallest double, about 1e-308, and rounds to 0).
  double last = 0;
  for (int b = 250; b <= 1000; b += 50) {
    const double p = drivers::mcnemar_exact_p(b, 2000 - b);
    EXPECT_EQ(p, drivers::mcnemar_exact_p(2000 - b, b));
    EXPECT_GT(p, last);
    EXPECT_LE(p, 1.0);
    last = p;
  }
  EXPECT_THROW(drivers::mcnemar_exact_p(-1, 3), std::invalid_argument);
}

TEST(MonteCarloCompare, PairsMatchABruteForceCountOverTheRecords) {
  const std::vector<std::string> names = {"open-loop", "paper", "mine"};
  const int worlds = 157;
  drivers::MonteCarloResult r = made_up_result(names, worlds, 5);
  // The records in a scrambled order: the comparison must not rely on their order.
  std::shuffle(r.records.begin(), r.records.end(), std::mt19937_64(9));
  const drivers::ControllerComparison c = drivers::compare_controllers(r);
  ASSERT_EQ(c.controllers.size(), 3u);
  ASSERT_EQ(c.pairs.size(), 3u);
  const auto find = [&](int world, const std::string& name) -> const drivers::RunRecord& {
    for (const auto& rec : r.records)
      if (rec.run == world && rec.controller == name) return rec;
    throw std::logic_error("missing record");
  };
  std::size_t k = 0;
  for (std::size_t a = 0; a < names.size(); ++a)
    for (std::size_t b = a + 1; b < names.size(); ++b, ++k) {
      const drivers::PairedComparison& p = c.pairs[k];
      SCOPED_TRACE(p.a + " vs " + p.b);
      EXPECT_EQ(p.a, names[a]);
      EXPECT_EQ(p.b, names[b]);
      int worlds_counted = 0, both = 0, only_a = 0, only_b = 0, neither = 0;
      for (int w = 0; w < worlds; ++w) {
        const auto& x = find(w, names[a]);
        const auto& y = find(w, names[b]);
        if (x.outcome == Outcome::kNumericalFailure || y.outcome == Outcome::kNumericalFailure)
          continue;
        ++worlds_counted;
        both += x.success && y.success;
        only_a += x.success && !y.success;
        only_b += !x.success && y.success;
        neither += !x.success && !y.success;
      }
      EXPECT_EQ(p.worlds, worlds_counted);
      EXPECT_EQ(p.both, both);
      EXPECT_EQ(p.only_a, only_a);
      EXPECT_EQ(p.only_b, only_b);
      EXPECT_EQ(p.neither, neither);
      EXPECT_GT(only_a + only_b, 0) << "the made-up worlds should disagree somewhere";
      EXPECT_EQ(p.p_value, drivers::mcnemar_exact_p(only_a, only_b));
    }
}

TEST(MonteCarloCompare, ReportsCountOutcomesCausesAndTheSuccessesMargins) {
  const std::vector<std::string> names = {"feedback", "paper"};
  const drivers::MonteCarloResult r = made_up_result(names, 300, 17);
  const drivers::ControllerComparison c = drivers::compare_controllers(r);
  ASSERT_EQ(c.controllers.size(), 2u);
  for (std::size_t i = 0; i < names.size(); ++i) {
    const drivers::ControllerReport& rep = c.controllers[i];
    SCOPED_TRACE(rep.name);
    EXPECT_EQ(rep.name, names[i]);
    EXPECT_EQ(rep.runs, 300);
    int successes = 0, failed = 0, outcome_total = 0, stops = 0, stop_total = 0;
    std::vector<double> duration, fn_min, friction;
    std::map<std::string, int> causes;
    for (const auto& rec : r.records) {
      if (rec.controller != names[i]) continue;
      failed += rec.outcome == Outcome::kNumericalFailure;
      if (rec.outcome == Outcome::kSafeStop) {
        ++stops;
        ++causes[rec.stop_cause ? control::to_string(*rec.stop_cause) : "other"];
      }
      if (!rec.success) continue;
      ++successes;
      duration.push_back(rec.duration_s);
      fn_min.push_back(rec.fn_min_ratio);
      friction.push_back(rec.mu_max / rec.mu);
    }
    EXPECT_EQ(rep.successes, successes);
    EXPECT_EQ(rep.numerical_failures, failed);
    const auto ci = drivers::wilson_interval(successes, 300 - failed);
    EXPECT_EQ(rep.ci.lo, ci.lo);
    EXPECT_EQ(rep.ci.hi, ci.hi);
    // Every outcome is listed, and the counts add up to the worlds.
    EXPECT_EQ(rep.outcomes.size(), 9u);  // success ... numerical_failure, invalid_world
    for (const auto& [kind, n] : rep.outcomes) outcome_total += n;
    EXPECT_EQ(outcome_total, 300);
    EXPECT_EQ(rep.outcomes.at("success"), successes);
    EXPECT_EQ(rep.outcomes.at("numerical_failure"), failed);
    EXPECT_EQ(rep.outcomes.at("safe_stop"), stops);
    EXPECT_EQ(rep.safe_stops, causes);
    for (const auto& [cause, n] : rep.safe_stops) stop_total += n;
    EXPECT_EQ(stop_total, stops);
    EXPECT_GT(rep.safe_stops.count("other"), 0u);
    // The margins are over the successes only.
    std::sort(duration.begin(), duration.end());
    std::sort(fn_min.begin(), fn_min.end());
    std::sort(friction.begin(), friction.end());
    EXPECT_EQ(rep.duration_s.n, successes);
    EXPECT_EQ(rep.duration_s.max, duration.back());
    EXPECT_EQ(rep.fn_min_ratio.min, fn_min.front());
    EXPECT_EQ(rep.friction_use.max, friction.back());
    EXPECT_LE(rep.friction_use.max, 1.0);
    EXPECT_EQ(rep.fn_min_ratio.median, drivers::quantile(fn_min, 0.5));
    EXPECT_EQ(rep.fn_min_ratio.p05, drivers::quantile(fn_min, 0.05));
    EXPECT_EQ(rep.friction_use.p95, drivers::quantile(friction, 0.95));
  }
}

TEST(MonteCarloCompare, RefusesRecordsThatDoNotTileTheWorlds) {
  const std::vector<std::string> names = {"open-loop", "paper"};
  drivers::MonteCarloResult r = made_up_result(names, 4, 1);
  drivers::MonteCarloResult repeated = r;
  repeated.records.push_back(repeated.records.front());
  EXPECT_THROW(drivers::compare_controllers(repeated), std::invalid_argument);
  drivers::MonteCarloResult missing = r;
  missing.records.pop_back();
  EXPECT_THROW(drivers::compare_controllers(missing), std::invalid_argument);
  drivers::MonteCarloResult stranger = r;
  stranger.records.back().controller = "transverse";
  EXPECT_THROW(drivers::compare_controllers(stranger), std::invalid_argument);
  // One controller: a report and no pairs.
  const drivers::ControllerComparison one =
      drivers::compare_controllers(made_up_result({"x"}, 3, 2));
  EXPECT_EQ(one.controllers.size(), 1u);
  EXPECT_TRUE(one.pairs.empty());
}

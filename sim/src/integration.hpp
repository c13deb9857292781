// The integrators (Dormand-Prince 5(4) and 8(5,3), classical RK4) with event location, shared by
// the rolling model's simulate() and the hybrid model's segments (sim/src/hybrid.cpp). Internal
// to sim/.
//
// One Integration runs one formulation (a Model: ReducedDiskRolling, ReducedDiskSliding,
// GeneralRolling in some phase) from a state until the end time or the first guard event. It
// keeps the active hand piece fixed over a segment and restarts at located junction crossings and
// at the motion's breakpoints (where the hand's acceleration jumps: the guards are evaluated there
// at once, so a violation caused by the jump is an event at that instant).
#pragma once

#include "dopri5_tableau.hpp"
#include "flatland/sim/roots.hpp"
#include "flatland/sim/simulate.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::sim::detail {

// Dormand-Prince 8(5,3) (Hairer, Norsett, Wanner, Solving ODEs I, and Hairer's DOP853): 12
// stages, stage 13 = f(t + h, y1) (FSAL), stages 14-16 only for the dense output. Indices are
// 0-based stages.
namespace dop853 {
constexpr int kStages = 12;
constexpr std::array<double, 16> c = {0.0,
                                      0.526001519587677318785587544488e-01,
                                      0.789002279381515978178381316732e-01,
                                      0.118350341907227396726757197510,
                                      0.281649658092772603273242802490,
                                      0.333333333333333333333333333333,
                                      0.25,
                                      0.307692307692307692307692307692,
                                      0.651282051282051282051282051282,
                                      0.6,
                                      0.857142857142857142857142857142,
                                      1.0,
                                      1.0,
                                      0.1,
                                      0.2,
                                      0.777777777777777777777777777778};
// a[i][j], j < i; rows 13-15 are the dense-output stages (they use stage 12 = f(t + h, y1)).
constexpr double a[16][16] = {
    {},
    {5.26001519587677318785587544488e-2},
    {1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2},
    {2.95875854768068491816892993775e-2, 0, 8.87627564304205475450678981324e-2},
    {2.41365134159266685502369798665e-1, 0, -8.84549479328286085344864962717e-1,
     9.24834003261792003115737966543e-1},
    {3.7037037037037037037037037037e-2, 0, 0, 1.70828608729473871279604482173e-1,
     1.25467687566822425016691814123e-1},
    {3.7109375e-2, 0, 0, 1.70252211019544039314978060272e-1, 6.02165389804559606850219397283e-2,
     -1.7578125e-2},
    {3.70920001185047927108779319836e-2, 0, 0, 1.70383925712239993810214054705e-1,
     1.07262030446373284651809199168e-1, -1.53194377486244017527936158236e-2,
     8.27378916381402288758473766002e-3},
    {6.24110958716075717114429577812e-1, 0, 0, -3.36089262944694129406857109825,
     -8.68219346841726006818189891453e-1, 2.75920996994467083049415600797e1,
     2.01540675504778934086186788979e1, -4.34898841810699588477366255144e1},
    {4.77662536438264365890433908527e-1, 0, 0, -2.48811461997166764192642586468,
     -5.90290826836842996371446475743e-1, 2.12300514481811942347288949897e1,
     1.52792336328824235832596922938e1, -3.32882109689848629194453265587e1,
     -2.03312017085086261358222928593e-2},
    {-9.3714243008598732571704021658e-1, 0, 0, 5.18637242884406370830023853209,
     1.09143734899672957818500254654, -8.14978701074692612513997267357,
     -1.85200656599969598641566180701e1, 2.27394870993505042818970056734e1,
     2.49360555267965238987089396762, -3.0467644718982195003823669022},
    {2.27331014751653820792359768449, 0, 0, -1.05344954667372501984066689879e1,
     -2.00087205822486249909675718444, -1.79589318631187989172765950534e1,
     2.79488845294199600508499808837e1, -2.85899827713502369474065508674,
     -8.87285693353062954433549289258, 1.23605671757943030647266201528e1,
     6.43392746015763530355970484046e-1},
    // row 12: the 8th-order weights b
    {5.42937341165687622380535766363e-2, 0, 0, 0, 0, 4.45031289275240888144113950566,
     1.89151789931450038304281599044, -5.8012039600105847814672114227,
     3.1116436695781989440891606237e-1, -1.52160949662516078556178806805e-1,
     2.01365400804030348374776537501e-1, 4.47106157277725905176885569043e-2},
    {5.61675022830479523392909219681e-2, 0, 0, 0, 0, 0, 2.53500210216624811088794765333e-1,
     -2.46239037470802489917441475441e-1, -1.24191423263816360469010140626e-1,
     1.5329179827876569731206322685e-1, 8.20105229563468988491666602057e-3,
     7.56789766054569976138603589584e-3, -8.298e-3},
    {3.18346481635021405060768473261e-2, 0, 0, 0, 0, 2.83009096723667755288322961402e-2,
     5.35419883074385676223797384372e-2, -5.49237485713909884646569340306e-2, 0, 0,
     -1.08347328697249322858509316994e-4, 3.82571090835658412954920192323e-4,
     -3.40465008687404560802977114492e-4, 1.41312443674632500278074618366e-1},
    {-4.28896301583791923408573538692e-1, 0, 0, 0, 0, -4.69762141536116384314449447206,
     7.68342119606259904184240953878, 4.06898981839711007970213554331,
     3.56727187455281109270669543021e-1, 0, 0, 0, -1.39902416515901462129418009734e-3,
     2.9475147891527723389556272149, -9.15095847217987001081870187138}};
// 5th-order error weights (stages 0-11).
constexpr std::array<double, 12> err5 = {0.1312004499419488073250102996e-1,
                                         0,
                                         0,
                                         0,
                                         0,
                                         -0.1225156446376204440720569753e1,
                                         -0.4957589496572501915214079952,
                                         0.1664377182454986536961530415e1,
                                         -0.3503288487499736816886487290,
                                         0.3341791187130174790297318841,
                                         0.8192320648511571246570742613e-1,
                                         -0.2235530786388629525884427845e-1};
// The 3rd-order estimate is b minus these (stages 0, 8, 11).
constexpr double bhh1 = 0.244094488188976377952755905512, bhh2 = 0.733846688281611857341361741547,
                 bhh3 = 0.220588235294117647058823529412e-1;
// Dense output: coefficients 4-7 of the interpolant are h * d[i] . k over the 16 stages.
constexpr double d[4][16] = {
    {-0.84289382761090128651353491142e1, 0, 0, 0, 0, 0.56671495351937776962531783590,
     -0.30689499459498916912797304727e1, 0.23846676565120698287728149680e1,
     0.21170345824450282767155149946e1, -0.87139158377797299206789907490,
     0.22404374302607882758541771650e1, 0.63157877876946881815570249290,
     -0.88990336451333310820698117400e-1, 0.18148505520854727256656404962e2,
     -0.91946323924783554000451984436e1, -0.44360363875948939664310572000e1},
    {0.10427508642579134603413151009e2, 0, 0, 0, 0, 0.24228349177525818288430175319e3,
     0.16520045171727028198505394887e3, -0.37454675472269020279518312152e3,
     -0.22113666853125306036270938578e2, 0.77334326684722638389603898808e1,
     -0.30674084731089398182061213626e2, -0.93321305264302278729567221706e1,
     0.15697238121770843886131091075e2, -0.31139403219565177677282850411e2,
     -0.93529243588444783865713862664e1, 0.35816841486394083752465898540e2},
    {0.19985053242002433820987653617e2, 0, 0, 0, 0, -0.38703730874935176555105901742e3,
     -0.18917813819516756882830838328e3, 0.52780815920542364900561016686e3,
     -0.11573902539959630126141871134e2, 0.68812326946963000169666922661e1,
     -0.10006050966910838403183860980e1, 0.77771377980534432092869265740,
     -0.27782057523535084065932004339e1, -0.60196695231264120758267380846e2,
     0.84320405506677161018159903784e2, 0.11992291136182789328035130030e2},
    {-0.25693933462703749003312586129e2, 0, 0, 0, 0, -0.15418974869023643374053993627e3,
     -0.23152937917604549567536039109e3, 0.35763911791061412378285349910e3,
     0.93405324183624310003907691704e2, -0.37458323136451633156875139351e2,
     0.10409964950896230045147246184e3, 0.29840293426660503123344363579e2,
     -0.43533456590011143754432175058e2, 0.96324553959188282948394950600e2,
     -0.39177261675615439165231486172e2, -0.14972683625798562581422125276e3}};
}  // namespace dop853

inline std::string at_text(double t, double s_h) {
  std::ostringstream os;
  os.precision(10);
  os << "at t=" << t << " s (s_h=" << s_h << ")";
  return os.str();
}

/// A condition that must hold over a segment: it fires where `value` goes from >= 0 to < 0. At
/// the start of a segment (and right after a motion breakpoint) a value below -tolerance fires at
/// once; a value within the tolerance is taken as the boundary the segment starts on.
struct Guard {
  EventKind kind;
  std::function<double(const Sample&)> value;
  double tolerance = 0;
};

/// Where a segment ended.
template <class State>
struct SegmentEnd {
  double t = 0;
  State y;
  Pieces pieces;
  std::optional<EventKind> fired;  ///< a guard (or kLeftBounds) ended it; none: the end time
  Sample first;                    ///< the sample at the start
  Sample last;                     ///< the sample at the end
};

template <class Model>
class Integration {
 public:
  using State = typename Model::State;
  static constexpr int N = Model::N;
  using Dense = std::array<State, 8>;  // interpolant coefficients (5 used unless dop853)

  Integration(const Model& model, const RunOptions& opt, RunResult& res, std::vector<Guard> guards)
      : model_(model), opt_(opt), res_(res), st_(res.stats), guards_(std::move(guards)) {}

  /// Integrate from (t, y) on `pieces` (y on the contact manifold) to opt.t_end, or to the first
  /// guard event, junction crossings and motion breakpoints included. When recording, the start
  /// sample and every step are appended to the run, in a new part of its trajectory.
  SegmentEnd<State> run_from(double t, State y, Pieces pieces);

  /// The sample at (t, y) on the active pieces (counted as an event evaluation).
  Sample sample(double t, const State& y) {
    ++st_.event_evals;
    return model_.sample(t, y, pieces_);
  }
  void set_pieces(const Pieces& p) { pieces_ = p; }

 private:
  void rhs(double t, const State& y, State& dy) {
    model_.derivative(t, y, pieces_, dy);
    ++st_.rhs_evals;
  }
  using Stages853 = std::array<State, 16>;
  /// One step of size h from (t, y) with k1 = f(t, y): y1, k7 = f(t + h, y1) and the scaled
  /// error norm (0 for RK4), and the dense output in `rc` except for DOP853, whose three extra
  /// stages are paid only for accepted recorded steps (dense_dop853). `trial` steps (event
  /// location on the step map) keep DOP853's stages out of the step's own (k853_).
  double attempt(double t, const State& y, const State& k1, double h, State& y1, State& k7,
                 Dense& rc, bool trial = false);
  double attempt_dop853(double t, const State& y, const State& k1, double h, State& y1, State& k13,
                        Stages853& k);
  /// DOP853's 7th-order interpolant of the last non-trial attempt (from k853_).
  void dense_dop853(double t, const State& y, const State& y1, double h, Dense& rc);
  double initial_step(double t, const State& y, const State& f0, double t_stop);
  void record(double t, const State& y, const Sample* s);
  /// The first guard violated at a segment's start (beyond its tolerance).
  std::optional<EventKind> violated(const Sample& s) const {
    for (const Guard& g : guards_)
      if (g.value(s) < -g.tolerance) return g.kind;
    return std::nullopt;
  }

  const Model& model_;
  const RunOptions& opt_;
  RunResult& res_;
  RunStats& st_;
  std::vector<Guard> guards_;
  Pieces pieces_;
  Stages853 k853_;
};

template <class Model>
double Integration<Model>::attempt_dop853(double t, const State& y, const State& k1, double h,
                                          State& y1, State& k13, Stages853& k) {
  using namespace dop853;
  k[0] = k1;
  for (int i = 1; i < kStages; ++i) {
    State yi = y;
    for (int j = 0; j < i; ++j)
      if (a[i][j] != 0) yi += (h * a[i][j]) * k[j];
    rhs(t + c[i] * h, yi, k[i]);
  }
  y1 = y;
  for (int j = 0; j < kStages; ++j)
    if (a[kStages][j] != 0) y1 += (h * a[kStages][j]) * k[j];
  rhs(t + h, y1, k[12]);
  k13 = k[12];
  // Hairer's error norm: the 5th-order estimate err5 ~ h^6, damped by the 3rd-order one
  // err3 ~ h^4 as err5^2 / sqrt(err5^2 + 0.01 err3^2) ~ h^8, so that the step size follows the
  // 8th-order solution's own error (steps ~ tol^(-1/8)) instead of the 5th-order estimate's.
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  double s5 = 0, s3 = 0;
  for (int n = 0; n < N; ++n) {
    const double sk = atol + rtol * std::max(std::abs(y[n]), std::abs(y1[n]));
    double e5n = 0, bn = 0;
    for (int j = 0; j < kStages; ++j) {
      e5n += err5[j] * k[j][n];
      bn += a[kStages][j] * k[j][n];
    }
    const double e3n = bn - bhh1 * k[0][n] - bhh2 * k[8][n] - bhh3 * k[11][n];
    s5 += (e5n / sk) * (e5n / sk);
    s3 += (e3n / sk) * (e3n / sk);
  }
  double deno = s5 + 0.01 * s3;
  if (deno <= 0) deno = 1;
  const double e = std::abs(h) * s5 / std::sqrt(N * deno);
  return std::isfinite(e) && y1.allFinite() ? e : std::numeric_limits<double>::infinity();
}

template <class Model>
void Integration<Model>::dense_dop853(double t, const State& y, const State& y1, double h,
                                      Dense& rc) {
  using namespace dop853;
  Stages853& k = k853_;
  for (int i = kStages + 1; i < 16; ++i) {
    State yi = y;
    for (int j = 0; j < i; ++j)
      if (a[i][j] != 0) yi += (h * a[i][j]) * k[j];
    rhs(t + c[i] * h, yi, k[i]);
  }
  rc[0] = y;
  rc[1] = y1 - y;
  rc[2] = h * k[0] - rc[1];
  rc[3] = rc[1] - h * k[12] - rc[2];
  for (int r = 0; r < 4; ++r) {
    rc[4 + r].setZero();
    for (int j = 0; j < 16; ++j)
      if (d[r][j] != 0) rc[4 + r] += (h * d[r][j]) * k[j];
  }
}

template <class Model>
double Integration<Model>::attempt(double t, const State& y, const State& k1, double h, State& y1,
                                   State& k7, Dense& rc, bool trial) {
  if (opt_.integrator.method == Method::kDormandPrince853) {
    if (!trial) return attempt_dop853(t, y, k1, h, y1, k7, k853_);
    Stages853 scratch;
    return attempt_dop853(t, y, k1, h, y1, k7, scratch);
  }
  if (opt_.integrator.method == Method::kRungeKutta4) {
    State k2, k3, k4;
    rhs(t + 0.5 * h, y + 0.5 * h * k1, k2);
    rhs(t + 0.5 * h, y + 0.5 * h * k2, k3);
    rhs(t + h, y + h * k3, k4);
    y1 = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    rhs(t + h, y1, k7);  // reused as the next step's k1; gives the Hermite dense output
    rc[0] = y;
    rc[1] = y1 - y;
    rc[2] = h * k1 - rc[1];
    rc[3] = rc[1] - h * k7 - rc[2];
    rc[4].setZero();
    return 0.0;
  }
  State k2, k3, k4, k5, k6;
  rhs(t + c2 * h, y + h * (a21 * k1), k2);
  rhs(t + c3 * h, y + h * (a31 * k1 + a32 * k2), k3);
  rhs(t + c4 * h, y + h * (a41 * k1 + a42 * k2 + a43 * k3), k4);
  rhs(t + c5 * h, y + h * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4), k5);
  rhs(t + h, y + h * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5), k6);
  y1 = y + h * (a71 * k1 + a73 * k3 + a74 * k4 + a75 * k5 + a76 * k6);
  rhs(t + h, y1, k7);
  const State err = h * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  double sum = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::max(std::abs(y[i]), std::abs(y1[i]));
    sum += (err[i] / sk) * (err[i] / sk);
  }
  rc[0] = y;
  rc[1] = y1 - y;
  rc[2] = h * k1 - rc[1];
  rc[3] = rc[1] - h * k7 - rc[2];
  rc[4] = h * (d1 * k1 + d3 * k3 + d4 * k4 + d5 * k5 + d6 * k6 + d7 * k7);
  const double e = std::sqrt(sum / N);
  return std::isfinite(e) && y1.allFinite() ? e : std::numeric_limits<double>::infinity();
}

// Hairer's starting step size heuristic.
template <class Model>
double Integration<Model>::initial_step(double t, const State& y, const State& f0, double t_stop) {
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  double dnf = 0, dny = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    dnf += (f0[i] / sk) * (f0[i] / sk);
    dny += (y[i] / sk) * (y[i] / sk);
  }
  double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : std::sqrt(dny / dnf) * 0.01;
  h = std::min({h, opt_.integrator.max_step, t_stop - t});
  State f1;
  rhs(t + h, y + h * f0, f1);
  double der2 = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    der2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
  }
  der2 = std::sqrt(der2) / h;
  const double der12 = std::max(std::abs(der2), std::sqrt(dnf));
  const double order = opt_.integrator.method == Method::kDormandPrince853 ? 8.0 : 5.0;
  const double h1 = der12 <= 1e-15 ? std::max(1e-6, h * 1e-3) : std::pow(0.01 / der12, 1.0 / order);
  return std::min({100 * h, h1, opt_.integrator.max_step});
}

template <class Model>
void Integration<Model>::record(double t, const State& y, const Sample* s) {
  if (!opt_.record) return;
  res_.steps.push_back(s ? *s : sample(t, y));
}

template <class Model>
SegmentEnd<typename Model::State> Integration<Model>::run_from(double t, State y, Pieces pieces) {
  const IntegratorSettings& is = opt_.integrator;
  const EventSettings& ev = opt_.events;
  const bool rk4 = is.method == Method::kRungeKutta4;
  const bool dop853 = is.method == Method::kDormandPrince853;
  const int terms = dop853 ? 8 : 5;
  pieces_ = pieces;
  SegmentEnd<State> end;

  if (opt_.record) {
    res_.trajectory.begin_part(
        N,
        [m = model_](double tt, const double* yy, const Pieces& p) {
          State s = Eigen::Map<const State>(yy);
          m.project(tt, s, p);
          return m.sample(tt, s, p);
        },
        terms, N == 10 ? 4 : 0);
  }
  Sample s_start = sample(t, y);
  end.first = s_start;
  record(t, y, &s_start);
  const auto stop_now = [&](EventKind kind, const Sample& s) {
    end.t = t;
    end.y = y;
    end.pieces = pieces_;
    end.fired = kind;
    end.last = s;
    return end;
  };
  if (auto kind = violated(s_start)) return stop_now(*kind, s_start);

  std::vector<double> stops;
  for (double b : model_.problem().motion->breakpoints())
    if (b > t && b < opt_.t_end) stops.push_back(b);
  std::sort(stops.begin(), stops.end());
  stops.push_back(opt_.t_end);

  State k1, y1, k7;
  Dense rc;
  bool need_k1 = true;
  double h = rk4 ? is.fixed_step : 0.0;
  double facold = 1e-4;  // PI step-size controller memory
  bool last_rejected = false;
  std::optional<EventKind> stopped;
  int zero_progress = 0;
  const bool need_force = !guards_.empty();

  for (double t_stop : stops) {
    while (t < t_stop && !stopped) {
      if (need_k1) {
        rhs(t, y, k1);
        need_k1 = false;
        if (!rk4 && h == 0.0) h = initial_step(t, y, k1, t_stop);
      }
      double h_try = rk4 ? is.fixed_step : std::min(h, is.max_step);
      if (t + 1.01 * h_try >= t_stop) h_try = t_stop - t;  // land exactly on the stop
      if (st_.steps + st_.rejected >= is.max_steps)
        throw std::runtime_error("integrator: step budget (" + std::to_string(is.max_steps) +
                                 ") exhausted " + at_text(t, model_.s_h(y)));
      const double err = attempt(t, y, k1, h_try, y1, k7, rc);
      if (!rk4 && err > 1.0) {
        ++st_.rejected;
        last_rejected = true;
        h = h_try * (!std::isfinite(err) ? 0.1
                     : dop853            ? std::max(1.0 / 3.0, 0.9 * std::pow(err, -1.0 / 8.0))
                                         : std::max(0.2, 0.9 * std::pow(err, -0.2)));
        if (h < 1e-14 * std::max(1.0, std::abs(t)))
          throw std::runtime_error("integrator: step size underflow " + at_text(t, model_.s_h(y)) +
                                   " (singular or non-finite dynamics)");
        continue;
      }
      if (!y1.allFinite())
        throw std::runtime_error("integrator: non-finite state " + at_text(t, model_.s_h(y)) +
                                 " (reduce integrator.step)");
      double t1 = (h_try == t_stop - t) ? t_stop : t + h_try;
      State y1p = y1;
      double drift = model_.project(t1, y1p, pieces_);

      // ---- events on (t, t1] ----
      const PieceInterval iv = model_.problem().hand->piece_interval(pieces_.hand);
      const double s1 = model_.s_h(y1p);
      enum Kind { kNone, kJunction, kGuard, kBounds } kind = kNone;
      EventKind guard_kind = EventKind::kLeftBounds;
      double t_event = t1, junction = 0;
      // Events are located on the integrator's own step map, h -> step(y, h), rather than on the
      // dense output: the step that then ends on the event lands on it by construction (a coarse
      // fixed step's Hermite interpolant can be far off), and g(h_try) is exactly g1.
      const double h_full = h_try;
      auto step_state = [&](double hh) {
        State out, k7_unused;
        Dense rc_unused;
        attempt(t, y, k1, hh, out, k7_unused, rc_unused, true);
        model_.project(t + hh, out, pieces_);
        return out;
      };
      auto locate = [&](const std::function<double(const State&, double)>& g, double g0,
                        double g1) {
        return t + brent_root([&](double hh) { return g(step_state(hh), t + hh); }, 0.0, h_full, g0,
                              g1, ev.time_tolerance)
                       .x;
      };
      if (s1 > iv.hi || s1 < iv.lo) {
        junction = s1 > iv.hi ? iv.hi : iv.lo;
        const double g0 = model_.s_h(y) - junction, g1 = s1 - junction;
        // A previous crossing may have landed a rounding error short of its junction; if the
        // disk turns back right there, it is already across at the start of this step.
        const double tj =
            (g0 > 0) == (g1 > 0) || g0 == 0
                ? t
                : locate([&](const State& s, double) { return model_.s_h(s) - junction; }, g0, g1);
        if (tj < t_event || kind == kNone) t_event = tj, kind = kJunction;
      }
      if (ev.s_h_bounds && (s1 < ev.s_h_bounds->first || s1 > ev.s_h_bounds->second)) {
        const double bound =
            s1 < ev.s_h_bounds->first ? ev.s_h_bounds->first : ev.s_h_bounds->second;
        const double g0 = model_.s_h(y) - bound, g1 = s1 - bound;
        const double tb =
            (g0 > 0) == (g1 > 0) || g0 == 0
                ? t
                : locate([&](const State& s, double) { return model_.s_h(s) - bound; }, g0, g1);
        if (tb < t_event || kind == kNone) t_event = tb, kind = kBounds;
      }
      Sample s_end;
      bool have_end = false;
      if (need_force) {
        s_end = sample(t1, y1p);
        have_end = true;
        for (const Guard& gd : guards_) {
          const double g0 = gd.value(s_start), g1 = gd.value(s_end);
          if (!(g1 < 0)) continue;
          // A segment may start a rounding error on the wrong side of a boundary it was meant
          // to leave (within the tolerance); if the value stays below zero, the guard holds no
          // longer: it fires at the start.
          const double tg =
              g0 < 0 ? t
                     : locate([&](const State& s, double tau) { return gd.value(sample(tau, s)); },
                              g0, g1);
          if (tg < t_event || kind == kNone) t_event = tg, kind = kGuard, guard_kind = gd.kind;
        }
      }
      if (kind != kNone) {
        // Guard against chattering: events that keep firing without time advancing.
        zero_progress = t_event <= t ? zero_progress + 1 : 0;
        if (zero_progress > 8)
          throw std::runtime_error("integrator: events repeat without progress " +
                                   at_text(t, model_.s_h(y)) + " (chattering at a junction)");
      }
      if (kind != kNone && t_event < t1) {
        // Stop exactly at the event: redo the step up to it, so no step straddles it.
        h_try = t_event - t;
        if (h_try > 0) {
          attempt(t, y, k1, h_try, y1, k7, rc);
          t1 = t_event;
          y1p = y1;
          drift = model_.project(t1, y1p, pieces_);
        } else {
          y1p = y;
          t1 = t;
        }
        have_end = false;
      }

      // ---- accept ----
      Sample s_new;
      if (h_try > 0) {
        ++st_.steps;
        st_.max_drift = std::max(st_.max_drift, drift);
        if (opt_.record) {
          if (dop853) dense_dop853(t, y, y1, h_try, rc);
          std::array<double, 8 * N> c;
          for (int j = 0; j < terms; ++j) Eigen::Map<State>(c.data() + j * N) = rc[j];
          res_.trajectory.append(t, h_try, pieces_, c.data());
        }
        const bool moved = drift > 0 && N == 10;
        t = t1;
        y = y1p;
        if (moved)
          need_k1 = true;
        else
          k1 = k7;
        if (opt_.record || kind != kNone || need_force) {
          s_new = have_end ? s_end : sample(t, y);
          st_.max_constraint_residual =
              std::max(st_.max_constraint_residual, s_new.constraint_residual);
          st_.max_redundant_residual =
              std::max(st_.max_redundant_residual, s_new.redundant_residual);
          record(t, y, &s_new);
          s_start = s_new;
        }
      }
      if (!rk4 && kind == kNone && dop853) {
        // Hairer's DOP853 control: plain I controller (beta = 0) on the h^8 error norm, growth
        // at most 6x and shrink at most 3x; no growth right after a rejection.
        const double fac =
            std::clamp(std::pow(std::max(err, 1e-30), 1.0 / 8.0) / 0.9, 1.0 / 6, 3.0);
        h = h_try / fac;
        if (last_rejected) h = std::min(h, h_try);
      } else if (!rk4 && kind == kNone) {
        // PI step-size control (Hairer's DOPRI5 constants).
        const double fac11 = std::pow(std::max(err, 1e-16), 0.17);
        const double fac = std::clamp(fac11 / std::pow(facold, 0.04) / 0.9, 0.1, 5.0);
        facold = std::max(err, 1e-4);
        h = h_try / fac;
      }
      last_rejected = false;
      switch (kind) {
        case kNone:
          break;
        case kJunction: {
          ++st_.junction_crossings;
          ++st_.restarts;
          RecordedEvent junction_event;
          junction_event.kind = EventKind::kJunction;
          junction_event.t = t;
          junction_event.s_h = model_.s_h(y);
          res_.events.push_back(junction_event);
          // The landing point may sit a rounding error short of the junction: pick the next
          // piece from the junction itself and the direction of crossing.
          const int d = junction == iv.hi ? +1 : -1;
          const int motion = pieces_.motion;
          pieces_ = model_.pieces_for(y, d);
          pieces_.hand = model_.problem().hand->piece_at(junction, d);
          pieces_.motion = motion;
          need_k1 = true;
          if (need_force) s_start = sample(t, y);
          break;
        }
        case kGuard:
          stopped = guard_kind;
          break;
        case kBounds:
          stopped = EventKind::kLeftBounds;
          break;
      }
    }
    if (stopped) break;
    if (t_stop < opt_.t_end) {  // the motion's acceleration jumps here: restart on its next segment
      ++st_.restarts;
      ++pieces_.motion;
      need_k1 = true;
      if (need_force) {
        // The forces jump with the acceleration: a guard the jump violates fires here and now.
        s_start = sample(t, y);
        if (auto kind = violated(s_start)) {
          record(t, y, &s_start);
          return stop_now(*kind, s_start);
        }
      }
    }
  }
  end.t = t;
  end.y = y;
  end.pieces = pieces_;
  end.fired = stopped;
  end.last = (opt_.record && !res_.steps.empty() && res_.steps.back().t == t) ? res_.steps.back()
                                                                              : sample(t, y);
  return end;
}

}  // namespace flatland::sim::detail

// The explicit Runge-Kutta steps flatland integrates with (Dormand-Prince 5(4) and 8(5,3),
// classical RK4), each with its dense output, written once for the planar runs (integration.hpp)
// and the spatial run (spatial_run.cpp). A step takes the right-hand side as a callable
// f(t, y, dy). Internal to sim/.
#pragma once

#include "dopri5_tableau.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

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

/// A step's dense output: Hairer's interpolant coefficients (5 used by DOPRI5 and RK4's Hermite
/// interpolant, 8 by DOP853), evaluated by dense_value.
template <class State>
using DenseCoefficients = std::array<State, 8>;
template <class State>
using Stages853 = std::array<State, 16>;

/// The interpolant of a step at theta in [0, 1], `terms` of its coefficients (5 or 8): Horner from
/// the innermost term outwards, term j multiplying the rest by (1 - theta) (odd j) or theta.
template <class State>
State dense_value(const DenseCoefficients<State>& rc, int terms, double theta) {
  const double th1 = 1.0 - theta;
  State v = rc[terms - 1];
  for (int j = terms - 2; j >= 1; --j) v = rc[j] + (j % 2 == 1 ? th1 : theta) * v;
  return rc[0] + theta * v;
}

/// Dormand-Prince 5(4): y1, k7 = f(t + h, y1), the dense output, and the scaled RMS error norm
/// (infinite for a non-finite step) over the first `controlled` components (all when negative):
/// quadratures carried beside the state (the energy audit's works) follow its steps without
/// steering them.
template <class State, class F>
double dopri5_step(F&& f, double t, const State& y, const State& k1, double h, double rtol,
                   double atol, State& y1, State& k7, DenseCoefficients<State>& rc,
                   int controlled = -1) {
  const int N = controlled < 0 ? static_cast<int>(y.size()) : controlled;
  State k2, k3, k4, k5, k6;
  f(t + c2 * h, y + h * (a21 * k1), k2);
  f(t + c3 * h, y + h * (a31 * k1 + a32 * k2), k3);
  f(t + c4 * h, y + h * (a41 * k1 + a42 * k2 + a43 * k3), k4);
  f(t + c5 * h, y + h * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4), k5);
  f(t + h, y + h * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5), k6);
  y1 = y + h * (a71 * k1 + a73 * k3 + a74 * k4 + a75 * k5 + a76 * k6);
  f(t + h, y1, k7);
  const State err = h * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
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

/// Classical RK4: y1, k7 = f(t + h, y1) (the next step's k1) and the cubic Hermite dense output.
template <class State, class F>
void rk4_step(F&& f, double t, const State& y, const State& k1, double h, State& y1, State& k7,
              DenseCoefficients<State>& rc) {
  State k2, k3, k4;
  f(t + 0.5 * h, y + 0.5 * h * k1, k2);
  f(t + 0.5 * h, y + 0.5 * h * k2, k3);
  f(t + h, y + h * k3, k4);
  y1 = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
  f(t + h, y1, k7);
  rc[0] = y;
  rc[1] = y1 - y;
  rc[2] = h * k1 - rc[1];
  rc[3] = rc[1] - h * k7 - rc[2];
  rc[4].setZero();
}

/// Dormand-Prince 8(5,3): y1, k13 = f(t + h, y1), the stages in `k` (for dop853_dense) and
/// Hairer's error norm over the first `controlled` components (all when negative).
template <class State, class F>
double dop853_step(F&& f, double t, const State& y, const State& k1, double h, double rtol,
                   double atol, State& y1, State& k13, Stages853<State>& k, int controlled = -1) {
  using namespace dop853;
  const int N = controlled < 0 ? static_cast<int>(y.size()) : controlled;
  k[0] = k1;
  for (int i = 1; i < kStages; ++i) {
    State yi = y;
    for (int j = 0; j < i; ++j)
      if (a[i][j] != 0) yi += (h * a[i][j]) * k[j];
    f(t + c[i] * h, yi, k[i]);
  }
  y1 = y;
  for (int j = 0; j < kStages; ++j)
    if (a[kStages][j] != 0) y1 += (h * a[kStages][j]) * k[j];
  f(t + h, y1, k[12]);
  k13 = k[12];
  // Hairer's error norm: the 5th-order estimate err5 ~ h^6, damped by the 3rd-order one
  // err3 ~ h^4 as err5^2 / sqrt(err5^2 + 0.01 err3^2) ~ h^8, so that the step size follows the
  // 8th-order solution's own error (steps ~ tol^(-1/8)) instead of the 5th-order estimate's.
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

/// DOP853's 7th-order interpolant of an accepted step from its stages `k` (three more stages).
template <class State, class F>
void dop853_dense(F&& f, double t, const State& y, const State& y1, double h, Stages853<State>& k,
                  DenseCoefficients<State>& rc) {
  using namespace dop853;
  for (int i = kStages + 1; i < 16; ++i) {
    State yi = y;
    for (int j = 0; j < i; ++j)
      if (a[i][j] != 0) yi += (h * a[i][j]) * k[j];
    f(t + c[i] * h, yi, k[i]);
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

/// Hairer's starting step size heuristic for a method of the given order, f0 = f(t, y), from
/// the first `controlled` components (all when negative).
template <class State, class F>
double starting_step(F&& f, double t, const State& y, const State& f0, double t_stop, double rtol,
                     double atol, double max_step, double order, int controlled = -1) {
  const int N = controlled < 0 ? static_cast<int>(y.size()) : controlled;
  double dnf = 0, dny = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    dnf += (f0[i] / sk) * (f0[i] / sk);
    dny += (y[i] / sk) * (y[i] / sk);
  }
  double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : std::sqrt(dny / dnf) * 0.01;
  h = std::min({h, max_step, t_stop - t});
  State f1;
  f(t + h, y + h * f0, f1);
  double der2 = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    der2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
  }
  der2 = std::sqrt(der2) / h;
  const double der12 = std::max(std::abs(der2), std::sqrt(dnf));
  const double h1 = der12 <= 1e-15 ? std::max(1e-6, h * 1e-3) : std::pow(0.01 / der12, 1.0 / order);
  return std::min({100 * h, h1, max_step});
}

}  // namespace flatland::sim::detail

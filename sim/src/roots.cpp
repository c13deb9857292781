#include "flatland/sim/roots.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace flatland::sim {

RootResult brent_root(const std::function<double(double)>& f, double a, double b, double fa,
                      double fb, double xtol, int max_evaluations) {
  constexpr double eps = std::numeric_limits<double>::epsilon();
  RootResult r;
  if (!std::isfinite(fa) || !std::isfinite(fb))
    throw std::invalid_argument("root finder: function is not finite at the bracket ends");
  if ((fa > 0 && fb > 0) || (fa < 0 && fb < 0))
    throw std::invalid_argument("root finder: the interval does not bracket a root");
  if (fa == 0) return {a, 0.0, 0, true};
  if (fb == 0) return {b, 0.0, 0, true};
  double c = a, fc = fa, d = b - a, e = d;
  while (r.evaluations < max_evaluations) {
    if ((fb > 0) == (fc > 0)) {
      c = a;
      fc = fa;
      d = e = b - a;
    }
    if (std::abs(fc) < std::abs(fb)) {
      a = b;
      b = c;
      c = a;
      fa = fb;
      fb = fc;
      fc = fa;
    }
    const double tol = 2.0 * eps * std::abs(b) + 0.5 * xtol;
    const double m = 0.5 * (c - b);
    if (std::abs(m) <= tol || fb == 0) {
      r.x = b;
      r.fx = fb;
      r.converged = true;
      return r;
    }
    if (std::abs(e) >= tol && std::abs(fa) > std::abs(fb)) {
      double p, q;
      const double s = fb / fa;
      if (a == c) {
        p = 2.0 * m * s;
        q = 1.0 - s;
      } else {
        const double qa = fa / fc, rr = fb / fc;
        p = s * (2.0 * m * qa * (qa - rr) - (b - a) * (rr - 1.0));
        q = (qa - 1.0) * (rr - 1.0) * (s - 1.0);
      }
      if (p > 0)
        q = -q;
      else
        p = -p;
      if (2.0 * p < std::min(3.0 * m * q - std::abs(tol * q), std::abs(e * q))) {
        e = d;
        d = p / q;
      } else {
        d = m;
        e = m;
      }
    } else {
      d = m;
      e = m;
    }
    a = b;
    fa = fb;
    b += std::abs(d) > tol ? d : (m > 0 ? tol : -tol);
    fb = f(b);
    ++r.evaluations;
    if (!std::isfinite(fb)) throw std::runtime_error("root finder: function became non-finite");
  }
  r.x = b;
  r.fx = fb;
  return r;
}

MinResult brent_minimize(const std::function<double(double)>& f, double a, double b, double xtol,
                         int max_evaluations) {
  constexpr double golden = 0.3819660112501051;
  constexpr double eps = std::numeric_limits<double>::epsilon();
  if (a > b) std::swap(a, b);
  double x = a + golden * (b - a), w = x, v = x;
  double fx = f(x), fw = fx, fv = fx;
  double d = 0, e = 0;
  MinResult r;
  r.evaluations = 1;
  while (r.evaluations < max_evaluations) {
    const double xm = 0.5 * (a + b);
    const double tol1 = std::sqrt(eps) * std::abs(x) + xtol / 3.0, tol2 = 2.0 * tol1;
    if (std::abs(x - xm) <= tol2 - 0.5 * (b - a)) break;
    bool golden_step = true;
    if (std::abs(e) > tol1) {
      double rr = (x - w) * (fx - fv), q = (x - v) * (fx - fw), p = (x - v) * q - (x - w) * rr;
      q = 2.0 * (q - rr);
      if (q > 0)
        p = -p;
      else
        q = -q;
      const double etemp = e;
      e = d;
      if (std::abs(p) < std::abs(0.5 * q * etemp) && p > q * (a - x) && p < q * (b - x)) {
        d = p / q;
        const double u = x + d;
        if (u - a < tol2 || b - u < tol2) d = xm > x ? tol1 : -tol1;
        golden_step = false;
      }
    }
    if (golden_step) {
      e = (x >= xm ? a : b) - x;
      d = golden * e;
    }
    const double u = x + (std::abs(d) >= tol1 ? d : (d > 0 ? tol1 : -tol1));
    const double fu = f(u);
    ++r.evaluations;
    if (fu <= fx) {
      if (u >= x)
        a = x;
      else
        b = x;
      v = w;
      fv = fw;
      w = x;
      fw = fx;
      x = u;
      fx = fu;
    } else {
      if (u < x)
        a = u;
      else
        b = u;
      if (fu <= fw || w == x) {
        v = w;
        fv = fw;
        w = u;
        fw = fu;
      } else if (fu <= fv || v == x || v == w) {
        v = u;
        fv = fu;
      }
    }
  }
  r.x = x;
  r.fx = fx;
  return r;
}

}  // namespace flatland::sim

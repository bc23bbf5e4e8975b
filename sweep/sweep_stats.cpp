#include "sweep/sweep_stats.h"

#include <algorithm>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>

#include "util/error.h"

namespace paircast {
namespace {

std::vector<double> finite(const std::vector<double>& values) {
  std::vector<double> out;
  for (double v : values)
    if (std::isfinite(v)) out.push_back(v);
  return out;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? NAN : s / static_cast<double>(v.size());
}

// The unbiased sample variance (n - 1 in the denominator); NaN below 2 values.
double variance(const std::vector<double>& v) {
  if (v.size() < 2) return NAN;
  const double m = mean(v);
  double s = 0;
  for (double x : v) s += (x - m) * (x - m);
  return s / static_cast<double>(v.size() - 1);
}

}  // namespace

double tQuantile95(double df) {
  if (!(df > 0) || !std::isfinite(df)) return NAN;
  return boost::math::quantile(boost::math::students_t_distribution<double>(df), 0.975);
}

Interval interval95(const std::vector<double>& values) {
  const std::vector<double> v = finite(values);
  Interval r;
  r.n = static_cast<int>(v.size());
  r.mean = mean(v);
  r.halfWidth = r.n < 2 ? NAN : tQuantile95(r.n - 1) * std::sqrt(variance(v) / r.n);
  return r;
}

Interval differenceInterval95(const std::vector<double>& a, const std::vector<double>& b) {
  const std::vector<double> x = finite(a), y = finite(b);
  Interval r;
  r.n = static_cast<int>(std::min(x.size(), y.size()));
  r.mean = mean(x) - mean(y);
  if (x.size() < 2 || y.size() < 2) {
    r.halfWidth = NAN;
    return r;
  }
  const double vx = variance(x) / x.size(), vy = variance(y) / y.size();
  if (vx + vy == 0) {
    r.halfWidth = 0;
    return r;
  }
  const double df =
      (vx + vy) * (vx + vy) / (vx * vx / (x.size() - 1.0) + vy * vy / (y.size() - 1.0));  // Welch
  r.halfWidth = tQuantile95(df) * std::sqrt(vx + vy);
  return r;
}

Interval pairedDifferenceInterval95(const std::vector<double>& a, const std::vector<double>& b) {
  PAIRCAST_CHECK(a.size() == b.size());
  std::vector<double> d;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::isfinite(a[i]) && std::isfinite(b[i])) d.push_back(a[i] - b[i]);
  return interval95(d);
}

bool excludesZero(const Interval& d) {
  return std::isfinite(d.halfWidth) && std::abs(d.mean) > d.halfWidth;
}

}  // namespace paircast

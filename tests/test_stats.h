// Statistical comparisons in tests: whether two samples may come from one distribution.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace paircast::testing {

// The two-sample Kolmogorov-Smirnov statistic: the largest distance between the two empirical
// distribution functions, over the values of both samples.
inline double ksStatistic(std::vector<double> a, std::vector<double> b) {
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  double d = 0;
  for (size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    const double x = std::min(a[i], b[j]);
    while (i < a.size() && a[i] <= x) ++i;
    while (j < b.size() && b[j] <= x) ++j;
    d = std::max(d,
                 std::abs(static_cast<double>(i) / a.size() - static_cast<double>(j) / b.size()));
  }
  return d;
}

// The two-sample Kolmogorov-Smirnov test at level `alpha`: success when the statistic stays below
// the critical value c(alpha) sqrt((n + m) / (n m)), c(alpha) = sqrt(-ln(alpha / 2) / 2) (1.628
// at 0.01; asymptotic, close from a hundred values a sample), so that p >= alpha.
inline ::testing::AssertionResult sameDistribution(const std::vector<double>& a,
                                                   const std::vector<double>& b,
                                                   double alpha = 0.01) {
  if (a.empty() || b.empty()) return ::testing::AssertionFailure() << "an empty sample";
  const double n = static_cast<double>(a.size()), m = static_cast<double>(b.size());
  const double d = ksStatistic(a, b);
  const double critical = std::sqrt(-std::log(alpha / 2) / 2) * std::sqrt((n + m) / (n * m));
  return (d < critical ? ::testing::AssertionSuccess() : ::testing::AssertionFailure())
         << "Kolmogorov-Smirnov statistic " << d << " against the critical value " << critical
         << " at alpha " << alpha << " (samples of " << a.size() << " and " << b.size() << ")";
}

}  // namespace paircast::testing

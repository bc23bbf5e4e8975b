// The statistics of a sweep with several seeds per set: each metric's mean over the seeds with
// the half-width of its 95 % Student t interval, and the interval of the difference of two sets'
// means (paired by seed, or Welch's for unpaired runs), from which summary.html says which
// differences are larger than their noise.
#pragma once

#include <string>
#include <vector>

namespace paircast {

// The two-sided 95 % quantile of Student's t with `df` degrees of freedom (df > 0, need not be
// whole): 12.706 at 1, 4.303 at 2, 1.960 as df grows. NaN when df is not positive or finite.
double tQuantile95(double df);

// A mean (or a difference of means) and the half-width of its 95 % interval.
struct Interval {
  double mean = 0;       // NaN without values
  double halfWidth = 0;  // NaN when there is no interval (fewer than 2 values on a side)
  int n = 0;             // values used (for a difference: the smaller side's)
};

// Over the finite values; those that are not (a run whose metric failed) are left out.
Interval interval95(const std::vector<double>& values);

// a's mean minus b's, with Welch's 95 % interval (unequal variances, Welch-Satterthwaite
// degrees of freedom). When both samples have no spread the half-width is 0; with fewer than
// 2 values in either it is NaN.
Interval differenceInterval95(const std::vector<double>& a, const std::vector<double>& b);

// The mean of a[i] - b[i] with the 95 % t-interval of those differences: for runs paired by
// seed, which share their initial weights and masks, so that only their data differs. Pairs
// with a value that is not finite are left out. a and b must have the same size.
Interval pairedDifferenceInterval95(const std::vector<double>& a, const std::vector<double>& b);

// Whether an interval of a difference excludes 0: false when its width is unknown (NaN).
bool excludesZero(const Interval& difference);

}  // namespace paircast

#include "util/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <set>

#include "util/random.h"

namespace paircast {
namespace {

// The mantissa of a step, 1, 2 or 5 when the step is round.
double mantissa(double step) {
  return step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
}

std::vector<std::string> labels(const plot::Ticks& t) {
  std::vector<std::string> out;
  for (double v : t.values) out.push_back(plot::tickLabel(v, t.step));
  return out;
}

TEST(PlotTicks, RoundStepsInsideTheRangeOverManyRanges) {
  Rng rng(12);
  for (int trial = 0; trial < 20000; ++trial) {
    // Spans from 1e-6 to 1e8, starting up to 1e5 spans away from 0.
    const double b = rng.uniform(-6, 8);
    const double span = std::pow(10.0, b);
    const double lo =
        rng.uniform() < 0.2 ? 0.0 : rng.uniform(-1, 1) * std::pow(10.0, b + rng.uniform(-3, 5));
    const double hi = lo + span;
    const int target = 3 + static_cast<int>(rng.below(8));
    const plot::Ticks t = plot::ticks(lo, hi, target);
    SCOPED_TRACE(testing::Message() << "[" << lo << ", " << hi << "] target " << target);
    ASSERT_GT(t.step, 0);
    const double m = mantissa(t.step);
    EXPECT_TRUE(std::abs(m - 1) < 1e-9 || std::abs(m - 2) < 1e-9 || std::abs(m - 5) < 1e-9)
        << "step " << t.step;
    // The smallest round step that is at least span / target.
    EXPECT_GE(t.step, (hi - lo) / target * (1 - 1e-9));
    const double smaller = t.step / (std::abs(m - 5) < 1e-9 ? 2.5 : 2);
    EXPECT_LT(smaller, (hi - lo) / target * (1 + 1e-9));
    ASSERT_LE(t.values.size(), static_cast<size_t>(target + 1));
    if (target >= 5) ASSERT_GE(t.values.size(), 2u);
    for (size_t i = 0; i < t.values.size(); ++i) {
      const double v = t.values[i];
      EXPECT_GE(v, lo - 1e-9 * t.step);
      EXPECT_LE(v, hi + 1e-9 * t.step);
      EXPECT_NEAR(v / t.step, std::round(v / t.step), 1e-6) << v;
      if (i > 0) EXPECT_NEAR(v - t.values[i - 1], t.step, 1e-6 * t.step);
    }
    // Labels: distinct, never "-0", and they read back as the tick.
    const auto names = labels(t);
    EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
    for (size_t i = 0; i < names.size(); ++i) {
      if (t.values[i] == 0) EXPECT_NE(names[i][0], '-') << names[i];
      EXPECT_NEAR(std::strtod(names[i].c_str(), nullptr), t.values[i], 1e-6 * t.step) << names[i];
    }
  }
}

TEST(PlotTicks, ReadableLabelsOnTypicalAxes) {
  // A histogram's count axis, once labelled 6.04, 12.1, 18.1, 24.2.
  EXPECT_EQ(labels(plot::ticks(0, 24.16)), (std::vector<std::string>{"0", "5", "10", "15", "20"}));
  EXPECT_EQ(labels(plot::ticks(0, 1)),
            (std::vector<std::string>{"0.0", "0.2", "0.4", "0.6", "0.8", "1.0"}));
  EXPECT_EQ(labels(plot::ticks(0.1, 0.5)),
            (std::vector<std::string>{"0.1", "0.2", "0.3", "0.4", "0.5"}));
  EXPECT_EQ(labels(plot::ticks(-0.5, 0.5)),
            (std::vector<std::string>{"-0.4", "-0.2", "0.0", "0.2", "0.4"}));
  EXPECT_EQ(labels(plot::ticks(0, 180)), (std::vector<std::string>{"0", "50", "100", "150"}));
  EXPECT_EQ(labels(plot::ticks(0, 599)),
            (std::vector<std::string>{"0", "100", "200", "300", "400", "500"}));
  EXPECT_EQ(labels(plot::ticks(0.612, 0.655)),
            (std::vector<std::string>{"0.62", "0.63", "0.64", "0.65"}));
  EXPECT_EQ(labels(plot::ticks(0, 4e6)),
            (std::vector<std::string>{"0", "1e+06", "2e+06", "3e+06", "4e+06"}));
  EXPECT_EQ(labels(plot::ticks(0, 4e-5)),
            (std::vector<std::string>{"0", "1e-05", "2e-05", "3e-05", "4e-05"}));
  for (double hi : {1.0, 7.5, 24.16, 180.0, 999.0, 5e4})
    for (const auto& s : labels(plot::ticks(0, hi))) EXPECT_LE(s.size(), 5u) << s;
}

TEST(PlotTicks, BadRangesGiveNoTickOrOne) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (auto [lo, hi] : std::vector<std::pair<double, double>>{
           {nan, 1}, {0, nan}, {nan, nan}, {-inf, 0}, {0, inf}, {-inf, inf}, {1, 0}, {2, -2}}) {
    const plot::Ticks t = plot::ticks(lo, hi);
    EXPECT_TRUE(t.values.empty()) << lo << " " << hi;
    EXPECT_EQ(t.step, 0);
  }
  // Equal ends, or ends a double barely tells apart: one tick, at the low end.
  for (double v : {0.0, 3.0, -2.5, 1e-300, 1e300}) {
    const plot::Ticks t = plot::ticks(v, v);
    ASSERT_EQ(t.values.size(), 1u) << v;
    EXPECT_EQ(t.values[0], v);
  }
  EXPECT_EQ(plot::ticks(1, 1 + 1e-15).values.size(), 1u);
  EXPECT_EQ(plot::ticks(0, 1e-320).values.size(), 1u);  // a subnormal span
  // Ends near the largest double: the span overflows, the ticks do not.
  const plot::Ticks huge = plot::ticks(-1e308, 1e308);
  EXPECT_GE(huge.values.size(), 2u);
  for (double v : huge.values) EXPECT_TRUE(std::isfinite(v));
  // A target below 1 counts as 1.
  EXPECT_EQ(plot::ticks(0, 10, 0).values, (std::vector<double>{0, 10}));
  EXPECT_EQ(plot::ticks(0, 10, -3).values, (std::vector<double>{0, 10}));
  // Labels of values that are not finite do not crash.
  EXPECT_FALSE(plot::tickLabel(std::nan(""), 1).empty());
  EXPECT_FALSE(plot::tickLabel(1, std::nan("")).empty());
}

TEST(PlotCharts, AxesCarryTheRoundTicks) {
  std::vector<double> edges, counts;
  for (int i = 0; i <= 20; ++i) edges.push_back(i / 20.0);
  for (int i = 0; i < 20; ++i) counts.push_back(i % 7 * 3.3);
  const std::string h = plot::histogram(edges, counts, {"covis", "covis", "pairs"});
  EXPECT_NE(h.find(">0.4</text>"), std::string::npos);
  EXPECT_NE(h.find(">10</text>"), std::string::npos);
  EXPECT_EQ(h.find(">6.04</text>"), std::string::npos);
  plot::Series s;
  s.label = "loss";
  s.x = {0, 100, 200, 300};
  s.y = {1.05, 0.8, 0.7, 0.62};
  const std::string l = plot::lines({s}, {"loss", "step", "loss"});
  EXPECT_NE(l.find(">300</text>"), std::string::npos);
  EXPECT_NE(l.find(">0.8</text>"), std::string::npos);
  // An empty chart and one with a single point still make an SVG.
  EXPECT_NE(plot::lines({}, {}).find("</svg>"), std::string::npos);
  s.x = {5};
  s.y = {2};
  EXPECT_NE(plot::lines({s}, {}).find("</svg>"), std::string::npos);
}

TEST(PlotCharts, ErrorBarsAreDrawnAndWidenTheAxis) {
  plot::Series s;
  s.label = "delta1";
  s.x = {0.15, 0.55, 0.95, 1.2};
  s.y = {1.05, 0.8, 0.7, 0.62};
  const std::string plain = plot::lines({s}, {"d", "covis", "delta1"});
  EXPECT_EQ(plain.find("stroke-width='1.5'"), std::string::npos);
  EXPECT_EQ(plain.find(">1.6</text>"), std::string::npos);
  s.yErr = {0.5, NAN, 0.0, 0.1};  // bars on the first and the last point only
  const std::string bars = plot::lines({s}, {"d", "covis", "delta1"});
  size_t count = 0;
  for (size_t at = bars.find("stroke-width='1.5'"); at != std::string::npos;
       at = bars.find("stroke-width='1.5'", at + 1))
    ++count;
  EXPECT_EQ(count, 2u);
  EXPECT_NE(bars.find(">1.6</text>"), std::string::npos);  // the axis reaches 1.05 + 0.5
}

}  // namespace
}  // namespace paircast

#include "sweep/sweep_stats.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "sweep/sweep_report.h"

namespace paircast {
namespace {

TEST(SweepStats, StudentQuantilesFromTheTables) {
  EXPECT_NEAR(tQuantile95(1), 12.7062, 1e-4);
  EXPECT_NEAR(tQuantile95(2), 4.3027, 1e-4);
  EXPECT_NEAR(tQuantile95(4), 2.7764, 1e-4);
  EXPECT_NEAR(tQuantile95(30), 2.0423, 1e-4);
  EXPECT_NEAR(tQuantile95(1e7), 1.95996, 1e-4);
  EXPECT_GT(tQuantile95(2.5), tQuantile95(3));  // fractional degrees of freedom (Welch)
  EXPECT_LT(tQuantile95(2.5), tQuantile95(2));
  EXPECT_TRUE(std::isnan(tQuantile95(0)));
  EXPECT_TRUE(std::isnan(tQuantile95(-1)));
  EXPECT_TRUE(std::isnan(tQuantile95(NAN)));
}

TEST(SweepStats, IntervalOfTheMean) {
  // {1, 2, 3}: mean 2, s = 1, half-width t(0.975, 2) / sqrt(3).
  const Interval a = interval95({1, 2, 3});
  EXPECT_EQ(a.n, 3);
  EXPECT_DOUBLE_EQ(a.mean, 2);
  EXPECT_NEAR(a.halfWidth, 4.302653 / std::sqrt(3.0), 1e-6);
  // Non-finite values (a run whose metric failed) are left out.
  const Interval b = interval95({1, NAN, 2, INFINITY, 3});
  EXPECT_EQ(b.n, 3);
  EXPECT_DOUBLE_EQ(b.halfWidth, a.halfWidth);
  // One value: a mean, no interval; none: neither.
  const Interval one = interval95({0.5});
  EXPECT_DOUBLE_EQ(one.mean, 0.5);
  EXPECT_TRUE(std::isnan(one.halfWidth));
  EXPECT_TRUE(std::isnan(interval95({}).mean));
  // No spread: a zero half-width.
  EXPECT_DOUBLE_EQ(interval95({0.25, 0.25, 0.25}).halfWidth, 0);
}

TEST(SweepStats, WelchIntervalOfADifference) {
  // Equal spreads: s^2 = 1 each, se = sqrt(2/3), df = 4.
  const Interval d = differenceInterval95({1, 2, 3}, {4, 5, 6});
  EXPECT_DOUBLE_EQ(d.mean, -3);
  EXPECT_NEAR(d.halfWidth, 2.776445 * std::sqrt(2.0 / 3.0), 1e-6);
  EXPECT_TRUE(excludesZero(d));
  // One side without spread: df = n - 1 of the other, se = sqrt(1/3).
  const Interval e = differenceInterval95({0, 0, 0}, {1, 2, 3});
  EXPECT_DOUBLE_EQ(e.mean, -2);
  EXPECT_NEAR(e.halfWidth, 4.302653 / std::sqrt(3.0), 1e-6);
  EXPECT_FALSE(excludesZero(e));  // 2 < 2.484
  // Neither has spread: any difference is beyond its (zero) interval, and none is not.
  EXPECT_TRUE(excludesZero(differenceInterval95({1, 1}, {2, 2})));
  EXPECT_FALSE(excludesZero(differenceInterval95({1, 1}, {1, 1})));
  // One seed on a side: no interval, so never called a difference.
  const Interval f = differenceInterval95({1}, {5, 6, 7});
  EXPECT_TRUE(std::isnan(f.halfWidth));
  EXPECT_FALSE(excludesZero(f));
}

TEST(SweepStats, PairedIntervalOfADifference) {
  // Runs that share their seeds' noise: the differences are steady, though each side spreads.
  const std::vector<double> a = {0.50, 0.60, 0.70}, b = {0.45, 0.56, 0.64};
  const Interval p = pairedDifferenceInterval95(a, b);  // differences 0.05, 0.04, 0.06
  EXPECT_NEAR(p.mean, 0.05, 1e-12);
  EXPECT_NEAR(p.halfWidth, 4.302653 * 0.01 / std::sqrt(3.0), 1e-6);
  EXPECT_EQ(p.n, 3);
  EXPECT_TRUE(excludesZero(p));
  EXPECT_FALSE(excludesZero(differenceInterval95(a, b)));  // Welch's cannot tell
  // A pair with a non-finite side is left out.
  const Interval q = pairedDifferenceInterval95({0.5, NAN, 0.7}, {0.45, 0.5, 0.64});
  EXPECT_EQ(q.n, 2);
  EXPECT_NEAR(q.mean, 0.055, 1e-12);
}

nlohmann::json run(const std::string& set, const std::string& task, double center, int seed,
                   double xv, double delta1) {
  return {{"set", set},
          {"task", task},
          {"mode", task == "mae" ? "mae" : "bin"},
          {"center", task == "mae" ? nlohmann::json() : nlohmann::json(center)},
          {"trained_on", task == "mae" ? "bin_0.55" : set},
          {"pairs", 64},
          {"mean_covis", center},
          {"seed_index", seed},
          {"train_loss", 0.5},
          {"xv_loss", xv},
          {"probe_delta1", delta1},
          {"probe_absrel", 1 - delta1},
          {"probe_rmse", 2 - delta1}};
}

TEST(SweepReport, RowsPerSetWithMeansAndIntervals) {
  nlohmann::json runs = nlohmann::json::array();
  for (int k = 0; k < 3; ++k) {
    runs.push_back(run("bin_0.15", "croco", 0.15, k, 0.6 + 0.01 * k, 0.40 + 0.01 * k));
    runs.push_back(run("mae", "mae", 0, k, 0.7, 0.30));
  }
  const nlohmann::json rows = aggregateRuns(runs);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0]["set"], "bin_0.15");
  EXPECT_EQ(rows[1]["set"], "mae");
  EXPECT_EQ(rows[0]["seeds"], 3);
  EXPECT_NEAR(rows[0]["xv_loss_mean"].get<double>(), 0.61, 1e-12);
  EXPECT_NEAR(rows[0]["xv_loss_ci95"].get<double>(), 4.302653 * 0.01 / std::sqrt(3.0), 1e-8);
  EXPECT_NEAR(rows[0]["probe_delta1_mean"].get<double>(), 0.41, 1e-12);
  EXPECT_DOUBLE_EQ(rows[1]["probe_delta1_ci95"].get<double>(), 0);
  EXPECT_TRUE(rows[1]["center"].is_null());
  EXPECT_EQ(rows[1]["task"], "mae");
}

// Three bins and mae over three seeds; bin 0.55 is far ahead in delta1 (beyond every interval)
// and level with the others in the completion loss (within it).
nlohmann::json syntheticResults(double gap, int seeds = 3) {
  nlohmann::json runs = nlohmann::json::array(), random = nlohmann::json::array();
  const double noise[] = {-0.01, 0.0, 0.01};
  for (int k = 0; k < seeds; ++k) {
    const double e = noise[k];
    runs.push_back(run("bin_0.15", "croco", 0.15, k, 0.62 + e, 0.40 + e));
    runs.push_back(run("bin_0.55", "croco", 0.55, k, 0.62 - e, 0.40 + gap + e));
    runs.push_back(run("bin_0.95", "croco", 0.95, k, 0.62 + e, 0.40 - e));
    runs.push_back(run("mae", "mae", 0, k, 0.30, 0.40 + e));
    random.push_back(run("random_encoder", "croco", 0, k, 1.3 + e, 0.35 + e));
  }
  return {{"runs", runs}, {"random_runs", random}, {"reference_set", "bin_0.55"}};
}

std::string joined(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

TEST(SweepReport, VerdictsSayWhichDifferencesAreBeyondTheirIntervals) {
  const std::string v = joined(sweepVerdicts(syntheticResults(0.1)));
  EXPECT_NE(v.find("depth probe delta1: the best is bin_0.55, 0.500 \u00b1 0.025. Behind it by "
                   "more than the interval: bin_0.15"),
            std::string::npos)
      << v;
  // The completion loss: all three sets level, mae's (another task) not compared.
  EXPECT_NE(v.find("Behind it by more than the interval: none. Within the interval of it: "),
            std::string::npos)
      << v;
  const size_t xv = v.find("held-out completion loss (covis ~0.5): the best");
  ASSERT_NE(xv, std::string::npos);
  EXPECT_EQ(v.substr(xv, v.find('\n', xv) - xv).find("mae"), std::string::npos) << v;
  // A verdict per probe: ahead in the depth probe, level in the completion loss.
  const std::string claim1 = "Claim 1, covis near 0.5 beats low and high covis, on the ";
  EXPECT_NE(v.find(claim1 + "held-out completion loss (covis ~0.5): is not resolved at this scale"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find(claim1 + "depth probe delta1: holds (bin_0.55's gain, positive when it is "
                            "better, with the paired 95 % interval over the seeds: vs bin_0.15 "
                            "+0.100 \u00b1 0.000; vs bin_0.95 +0.100 \u00b1 0.050)"),
            std::string::npos)
      << v;
  const std::string claim2 = "Claim 2, cross-view completion beats auto-completion (MAE), on the ";
  EXPECT_NE(v.find(claim2 + "depth probe delta1: holds"), std::string::npos) << v;
  EXPECT_NE(v.find(claim2 + "held-out completion loss (covis ~0.5): not compared: mae is another "
                            "task"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find(claim2 + "cross-attention correspondence PCK@1 patch: not compared: mae has no "
                            "reference view"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find(claim1 + "cross-attention correspondence PCK@1 patch: no figures"),
            std::string::npos)
      << v;  // these runs have no such probe
  // Without the gap, bin 0.55 wins nothing beyond the intervals.
  const std::string level = joined(sweepVerdicts(syntheticResults(0.0)));
  EXPECT_NE(level.find(claim2 + "depth probe delta1: is not resolved at this scale"),
            std::string::npos)
      << level;
  // With one seed there are no intervals: nothing is called a difference.
  const std::string one = joined(sweepVerdicts(syntheticResults(0.1, 1)));
  EXPECT_NE(one.find(claim2 + "depth probe delta1: cannot be judged with fewer than 2 seeds"),
            std::string::npos)
      << one;
  EXPECT_NE(one.find("depth probe delta1: the best is bin_0.55, 0.490. With one seed there are no "
                     "intervals"),
            std::string::npos)
      << one;
  // A gap the other way is a claim that does not hold.
  const std::string worse = joined(sweepVerdicts(syntheticResults(-0.1)));
  EXPECT_NE(worse.find(claim2 + "depth probe delta1: does not hold"), std::string::npos) << worse;
}

// Fine-tuned figures of three bins, mae and random weights over three seeds (e: a seed's
// noise): bin 0.55 has the lowest flow error, beyond every interval; random weights have the best
// depth; `randomFlow` is random weights' flow error (plus e).
nlohmann::json fineTunedResults(double randomFlow) {
  nlohmann::json r = syntheticResults(0.0);
  const double noise[] = {-0.01, 0.0, 0.01};
  const std::map<std::string, std::pair<double, double>> flow = {
      {"bin_0.15", {9.5, 1}}, {"bin_0.55", {9.0, 2}}, {"bin_0.95", {9.4, -1}}, {"mae", {9.6, 1}}};
  for (auto& run : r["runs"]) {
    const auto [base, scale] = flow.at(run["set"]);
    const double e = noise[run["seed_index"].get<int>()];
    run["ft_flow_aepe"] = base + scale * e;
    run["ft_depth_delta1"] = 0.4 + e;
  }
  for (auto& run : r["random_runs"]) {
    const double e = noise[run["seed_index"].get<int>()];
    run["ft_flow_aepe"] = randomFlow + e;
    run["ft_depth_delta1"] = 0.6 + e;
  }
  return r;
}

TEST(SweepReport, FineTunedVerdictsJudgeBothClaimsAndTheInstrument) {
  const std::string v = joined(sweepVerdicts(fineTunedResults(10.0)));
  const std::string flow = "on the fine-tuned flow AEPE (px): ";
  EXPECT_NE(v.find("Claim 1, covis near 0.5 beats low and high covis, " + flow +
                   "holds (bin_0.55's gain, positive when it is better, with the paired 95 % "
                   "interval over the seeds: vs bin_0.15 +0.500 \u00b1 0.025; vs bin_0.95 "
                   "+0.400 \u00b1 0.075)"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find("Claim 2, cross-view completion beats auto-completion (MAE), its encoder with "
                   "a random decoder, " +
                   flow +
                   "holds (bin_0.55's gain, positive when it is "
                   "better, with the paired 95 % interval over the seeds: vs mae +0.600 \u00b1 "
                   "0.025)"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find("Claim 2, cross-view pre-training beats random weights, " + flow + "holds"),
            std::string::npos)
      << v;
  // Random weights fine-tuned to a better depth: the claim does not hold there.
  EXPECT_NE(v.find("Claim 2, cross-view pre-training beats random weights, on the fine-tuned "
                   "depth delta1: does not hold (bin_0.55's gain, positive when it is better, "
                   "with the paired 95 % interval over the seeds: vs random_encoder -0.200 "
                   "\u00b1 0.000)"),
            std::string::npos)
      << v;
  EXPECT_NE(v.find("fine-tuned depth delta1: better than random weights (fine-tuned from "
                   "scratch) (0.600 \u00b1 0.025) by more than the interval: none."),
            std::string::npos)
      << v;
  // The widest paired half-width between two sets is bin_0.55 against bin_0.95's (3e: 0.075),
  // against a quarter of the gap 10.0 - 9.0.
  EXPECT_NE(v.find("Instrument, fine-tuned flow AEPE (px): decides. The widest 95 % half-width "
                   "of the difference between two sets (bin_0.55 and bin_0.95) is 0.075, 0.3x a "
                   "quarter of the gap between random weights (10.000) and the best pre-trained "
                   "run (bin_0.55, 9.000): 1.000 / 4 = 0.250."),
            std::string::npos)
      << v;
  // A gap of 0.05: 0.0745 is 6.0 times a quarter of it. The differences' spread is 0.03, and
  // t(n - 1) 0.03 / sqrt(n) <= 0.0125 first at n = 25 (t(24) = 2.064; at 24, t(23) = 2.069).
  const std::string narrow = joined(sweepVerdicts(fineTunedResults(9.05)));
  EXPECT_NE(narrow.find("Instrument, fine-tuned flow AEPE (px): does not decide. The widest 95 % "
                        "half-width of the difference between two sets (bin_0.55 and bin_0.95) "
                        "is 0.075, 6.0x a quarter of the gap between random weights (9.050) and "
                        "the best pre-trained run (bin_0.55, 9.000): 0.050 / 4 = 0.013. At this "
                        "budget about 25 seeds would decide"),
            std::string::npos)
      << narrow;
  const std::string none = joined(sweepVerdicts(fineTunedResults(8.0)));
  EXPECT_NE(none.find("Instrument, fine-tuned flow AEPE (px): does not decide. No pre-trained run "
                      "beats random weights (8.000; the best run, bin_0.55, 9.000)"),
            std::string::npos)
      << none;
  // Without fine-tuned figures there are no such lines.
  const std::string plain = joined(sweepVerdicts(syntheticResults(0.1)));
  EXPECT_EQ(plain.find("fine-tuned"), std::string::npos) << plain;
  EXPECT_EQ(plain.find("Instrument"), std::string::npos) << plain;
}

}  // namespace
}  // namespace paircast

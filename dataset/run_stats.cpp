#include "dataset/run_stats.h"

#include <algorithm>

namespace paircast {
namespace {

// A funnel as summary.json keeps it: by stage, the views that entered it, those it turned down
// (and wrongly, when audited), and its seconds.
nlohmann::json funnelJson(const std::vector<FunnelStage>& funnel) {
  nlohmann::json out = nlohmann::json::array();
  for (const FunnelStage& f : funnel)
    out.push_back({{"entered", f.entered},
                   {"turned_down", f.rejected},
                   {"false_rejections", f.falseRejections},
                   {"seconds", f.seconds}});
  return out;
}

}  // namespace

void RunStats::addIndex(const GenerationCost& spent, bool kept, double encodeSeconds,
                        double writeSeconds) {
  std::lock_guard<std::mutex> lock(mu_);
  sum_.add(spent);
  ++(kept ? accepted_ : failed_);
  candidates_ += spent.candidateCovis.size();
  // Pose sampling and bookkeeping: what generate() spent outside rendering, screening and covis.
  sampling_ += std::max(
      0.0, spent.totalSeconds - spent.renderSeconds - spent.screenSeconds - spent.covisSeconds);
  encode_ += encodeSeconds;
  write_ += writeSeconds;
}

void RunStats::addWrite(double seconds) {
  std::lock_guard<std::mutex> lock(mu_);
  write_ += seconds;
}

size_t RunStats::accepted() const {
  std::lock_guard<std::mutex> lock(mu_);
  return accepted_;
}

size_t RunStats::candidates() const {
  std::lock_guard<std::mutex> lock(mu_);
  return candidates_;
}

nlohmann::json RunStats::toJson(double seconds) const {
  std::lock_guard<std::mutex> lock(mu_);
  const GenerationCost& s = sum_;
  const nlohmann::json times = {{"render", s.renderSeconds},
                                {"render_kept", s.keptRenderSeconds},
                                {"render_wasted", s.renderSeconds - s.keptRenderSeconds},
                                {"screen", s.screenSeconds},
                                {"sampling", sampling_},
                                {"covis", s.covisSeconds},
                                {"encode", encode_},
                                {"write", write_}};
  const double total = std::max(
      s.renderSeconds + s.screenSeconds + sampling_ + s.covisSeconds + encode_ + write_, 1e-12);
  nlohmann::json split = nlohmann::json::object();
  for (const auto& [name, value] : times.items()) split[name] = value.get<double>() / total;
  return {{"pairs_this_run", accepted_},
          {"pairs_per_second", accepted_ / std::max(seconds, 1e-9)},
          {"failed_pairs", failed_},
          {"screening",
           {{"screened", s.screened},
            {"candidates_this_run", candidates_},
            {"false_rejections", s.falseRejections},
            {"references_given_up", s.referencesGivenUp},
            {"candidate_funnel", funnelJson(s.candidateFunnel)},
            {"reference_funnel", funnelJson(s.referenceFunnel)}}},
          {"renders",
           {{"full", s.fullRenders},
            {"kept", s.keptRenders},
            {"wasted", s.fullRenders - s.keptRenders},
            {"wasted_references", s.wastedReferenceRenders},
            {"wasted_candidates", s.wastedCandidateRenders},
            {"per_pair", accepted_ ? static_cast<double>(s.fullRenders) / accepted_ : 0.0}}},
          {"time_split", split},
          {"time_seconds", times}};
}

}  // namespace paircast

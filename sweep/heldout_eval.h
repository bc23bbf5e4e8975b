// The held-out evaluation of covis_sweep, the same for every run: the completion loss on
// held-out pairs at covis about 0.5 with fixed masks, the monocular depth probe on the frozen
// encoder (depth_probe.h), and the mechanism probes (mechanism_probe.h), on scenes never trained
// on.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "model/croco_net.h"
#include "model/precision.h"
#include "sweep/covis_sweep.h"
#include "sweep/depth_probe.h"
#include "sweep/mechanism_probe.h"

namespace paircast {

struct HeldOut {
  torch::Tensor img1, img2, mask;  // cross-view completion pairs at covis ~0.5
  ProbeData probeA, probeB;        // the depth probe's two halves (crossFitProbe)
  MechanismPairs mechanism;        // the mechanism probes' pairs
  nlohmann::json probeSettings;    // what the mechanism probes were made with
  Precision precision;             // what the evaluation computes in (--amp, on the CPU)
};

// Makes the evaluation data (the pairs at covis ~0.5 are generated once into heldout/xv; the
// rest is rendered again, the same each time): the first evalPairs pairs with one mask for every
// model, the depth probe's views in two halves, and the mechanism probes' pairs.
HeldOut loadHeldOut(const SweepConfig& config, const CroCoConfig& model,
                    const std::vector<std::string>& heldout);

// A model's held-out figures: its completion loss on its own task (with the reference view for
// "croco", without for "mae") over the held-out pairs and their fixed masks, the depth probe
// (probe_*), and the mechanism probes (mechanismProbes), at heldout.precision.
nlohmann::json evaluate(CroCoNet& model, const HeldOut& heldout, const std::string& task);

// Whether an eval.json holds the figures `evaluate` gives now for this held-out data: it was
// written with the same probe settings (one from before the mechanism probes, or with other
// --mechanism-* values, is evaluated again from its checkpoint).
bool evaluatedWith(const nlohmann::json& ev, const HeldOut& heldout);

// A floor for the depth probe: one half's mean log depth, everywhere in the other half (and back).
nlohmann::json constantDepthBaseline(const HeldOut& heldout);

}  // namespace paircast

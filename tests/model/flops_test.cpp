#include "model/flops.h"

#include <gtest/gtest.h>

#include "model/croco_net.h"

namespace paircast {
namespace {

TEST(Flops, ReproduceThePaperWithinFivePercent) {
  CroCoConfig cross = presetConfig("base"), cat = presetConfig("base");
  cat.decoder = "cat";
  const FlopCount a = countFlops(cross), b = countFlops(cat);
  EXPECT_EQ(a.params, 120076288);
  EXPECT_NEAR(b.params / 1e6, 111.0, 1.0);
  EXPECT_NEAR(a.flops / 50.2e9, 1.0, 0.05);
  EXPECT_NEAR(b.flops / 58.5e9, 1.0, 0.05);
  EXPECT_GT(a.flops_full, a.flops);  // attention, norms and activations come on top
}

TEST(Flops, ParameterFormulaMatchesTheModules) {
  for (const char* preset : {"tiny", "small"}) {
    for (const char* decoder : {"cross", "cat"}) {
      CroCoConfig c = presetConfig(preset);
      c.decoder = decoder;
      CroCoNet net(c);
      EXPECT_EQ(countFlops(c).params, countParameters(*net)) << preset << " " << decoder;
    }
  }
}

TEST(Flops, LinearLayersScaleWithTokens) {
  // Halving the mask ratio's visible share changes only the image-1 encoder term.
  CroCoConfig c = presetConfig("tiny");
  const double full = countFlops(c).flops;
  c.mask_ratio = 0.0;
  EXPECT_GT(countFlops(c).flops, full);
}

}  // namespace
}  // namespace paircast

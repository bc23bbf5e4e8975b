// The command-line flags of PairOptions, defined once for every command that generates pairs
// (generate_pairs, bench_generate): a flag added here reaches both. Ranges are checked by
// PairOptions::validate(), the one place they are written, when the job starts.
#pragma once

#include <CLI/CLI.hpp>

#include "covis/covisibility.h"
#include "dataset/pair_generator.h"

namespace paircast {

// Screening: --screen-resolution, the margins of its stages and checks, --screen-confirm,
// --screen-plain-tolerance and --give-up-after.
inline void addScreenFlags(CLI::App& app, PairOptions& o) {
  app.add_option("--screen-resolution", o.screenResolution,
                 "Screen candidates on depth at this resolution first, then at twice it while at "
                 "most a quarter of --resolution (0: off; default: a sixteenth of --resolution, "
                 "at least 16, off below 64)")
      ->check(CLI::NonNegativeNumber);  // -1 is the library's "automatic", not a user's value
  app.add_option("--screen-margin", o.screenCovisMargin,
                 "Screening keeps candidates whose 32x32 covis estimate is within this of the band "
                 "(16x16: 2.5 times it; other sides: see --screen-fine-margin)");
  app.add_option("--screen-fine-margin", o.screenFineMargin,
                 "The same margin for a 64x64 estimate; half of it per doubling beyond");
  app.add_flag_callback(
      "--screen-plain-tolerance", [&o] { o.screenScaleTolerance = false; },
      "Screening estimates take covis' own depth tolerances at every side (default: "
      "scaled with the side, docs/dataset.md); they then need wider margins: "
      "--screen-margin 0.18 --screen-fine-margin 0.04 --screen-glance-margin 0.25");
  app.add_option("--screen-frame-margin", o.screenFrameMargin,
                 "Before rendering, turn down candidates whose share of the reference inside their "
                 "frame is below --min-covis by more than this (default: off; 0.03 turns it on)");
  app.add_option("--screen-sight-margin", o.screenSightMargin,
                 "Before rendering, turn down candidates that see (shadow rays) a share of the "
                 "reference's points below --min-covis by more than this");
  app.add_option("--screen-glance-margin", o.screenGlanceCovisMargin,
                 "Turn down candidates whose 8x8 glance's share seen by the reference is below "
                 "--min-covis by more than this");
  app.add_flag("--screen-confirm", o.screenConfirm,
               "Screen candidates whose last estimate is near a bound of the band once more, at "
               "twice its side (costs more than it saves at 256, docs/dataset.md)");
  app.add_option("--give-up-after", o.giveUpAfter,
                 "Give a reference up after this many of its candidates in a row are turned down "
                 "before any render beyond 8x8 (0: never; the default)")
      ->check(CLI::NonNegativeNumber);
}

// Every flag of a pair: its images (--resolution, --hfov, --supersample), its views and their
// covis band (--views, --min-covis, --max-covis, --covis-normalize, --min-valid,
// --max-attempts), --save-covis-mask, and screening's (addScreenFlags).
inline void addPairFlags(CLI::App& app, PairOptions& o) {
  app.add_option("--resolution", o.resolution, "Image width and height, pixels (16..4096)");
  app.add_option("--hfov", o.hfov, "Horizontal field of view, degrees (1..179)");
  app.add_option("--min-covis", o.minCovis, "Keep pairs with covis >= this");
  app.add_option("--max-covis", o.maxCovis, "Keep pairs with covis <= this");
  app.add_option_function<std::string>(
         "--covis-normalize",
         [&o](const std::string& v) { o.covis.normalize = parseCovisNormalize(v); },
         "valid: divide by valid pixels (the paper); all: by all pixels (CroCo's generator)")
      ->check(CLI::IsMember({"valid", "all"}));
  app.add_option("--supersample", o.render.supersample, "s x s colour samples per pixel")
      ->check(CLI::Range(1, 4));
  app.add_option("--max-attempts", o.maxAttempts, "Second views tried per reference view");
  app.add_option("--min-valid", o.minValidFraction, "Minimum fraction of pixels with depth");
  app.add_option_function<std::string>(
         "--motion", [&o](const std::string& v) { o.sampler.motion = parseMotion(v); },
         "How the second view moves from the first: walk (CroCo's random walk on the floor, "
         "looking at the first view's mean point: wide pre-training pairs; the default) or near "
         "(a bounded motion of the first camera, as video frames move: flow-style pairs with "
         "small, dense motions; docs/dataset.md)")
      ->check(CLI::IsMember({"walk", "near"}));
  app.add_option("--near-translation", o.sampler.nearTranslation,
                 "--motion near: largest translation, metres (uniform in a ball, its vertical "
                 "part halved; default 0.25)");
  app.add_option("--near-rotation", o.sampler.nearRotation,
                 "--motion near: largest pan and tilt, degrees (roll: half; default 4)");
  app.add_option("--views", o.views,
                 "Views per sample (CroCo's views_count): view 1 and views-1 others, each with "
                 "covis in the band with view 1");
  addScreenFlags(app, o);
  app.add_flag("--save-covis-mask", o.covisMasks,
               "Also write 8-bit co-visibility masks (255: seen by the other view)");
}

}  // namespace paircast

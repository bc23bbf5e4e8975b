// dataset_report: an offline HTML page about a generated dataset (tar shards or CroCo's folder
// layout): the covis histogram, the joint distribution of distance and angle between the two
// views, the second view's position and heading relative to the first on the floor plane, sample
// pairs per covis bin with their covis, and the counts per scene.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "util/camera.h"

namespace paircast {

// One pair's metadata, as the report reads it.
struct PairRecord {
  std::string scene, key;
  double covis = 0;
  Camera camera[2];
};

// Distance between the optical centres, and the angle between the optical axes, in degrees.
double viewDistance(const PairRecord& p);
double viewAngleDegrees(const PairRecord& p);
// The second camera in the first one's floor frame: x to the right, y forward, both
// horizontal (up is the mean of the cameras' -y axes); heading is the second camera's
// horizontal forward direction in that frame (a unit vector).
struct FloorRelative {
  double x, y, headingX, headingY;
};
FloorRelative floorRelative(const PairRecord& p);

struct ReportOptions {
  std::string dir;       // generated output: *.tar shards, or pairs.txt + <scene>/metadata.json
  std::string keysFile;  // optional: only the pairs with these keys (shards only)
  std::string out;       // where report.html and its images go (default: dir)
  std::string title;     // default: the folder's name
  int samplesPerBin = 4;
  int bins = 10;  // covis bins of the sample grid and of the histogram's colouring
};

// Reads the pairs' records (shards first; else the CroCo layout). Throws paircast::Error naming
// the folder when it holds neither.
std::vector<PairRecord> readPairRecords(const std::string& dir, const std::string& keysFile = "");

// Writes <out>/report.html and <out>/report_files/*; returns a summary (pairs, per scene, ...).
nlohmann::json writeDatasetReport(const ReportOptions& options);

}  // namespace paircast

// dataset_report: an offline HTML report on generated pairs (shards or CroCo's layout).
#include <cstdio>

#include "dataset/dataset_report.h"
#include "tool_main.h"

using namespace paircast;

int main(int argc, char** argv) {
  ReportOptions o;
  CLI::App app{"Write report.html about a folder of generated pairs (shards or CroCo layout)"};
  app.add_option("dir", o.dir, "Output folder of generate_pairs")->required();
  app.add_option("--out", o.out, "Where report.html goes (default: DIR)");
  app.add_option("--keys", o.keysFile, "Only the pairs whose keys this file lists");
  app.add_option("--title", o.title, "Page title (default: the folder's name)");
  app.add_option("--samples-per-bin", o.samplesPerBin, "Sample pairs shown per covis bin")
      ->check(CLI::Range(0, 50));
  app.add_option("--bins", o.bins, "Covis bins of the sample grid")->check(CLI::Range(1, 50));
  return runTool("dataset_report", app, argc, argv, [&] {
    const nlohmann::json s = writeDatasetReport(o);
    std::printf("%s\n", s.dump().c_str());
    return 0;
  });
}

#include "util/html.h"

#include <gtest/gtest.h>

namespace paircast {
namespace {

// The reports' pages (dataset_report, covis_sweep's summary.html) are built from these pieces;
// their bytes are the pages' bytes.
TEST(Html, PageScaffolding) {
  EXPECT_EQ(html::style(1300),
            "<style>body{font-family:sans-serif;margin:24px;max-width:1300px}table{border-collapse:"
            "collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:"
            "#f3f3f3}</style>");
  EXPECT_EQ(html::style(10, ".grid{x:y}"),
            "<style>body{font-family:sans-serif;margin:24px;max-width:10px}table{border-collapse:"
            "collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:"
            "#f3f3f3}.grid{x:y}</style>");
  EXPECT_EQ(html::pageStart("T", "<style></style>"),
            "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>T</title>"
            "<style></style></head><body>\n");
  EXPECT_EQ(html::pageEnd(), "</body></html>\n");
  EXPECT_EQ(html::heading(2, "a b"), "<h2>a b</h2>\n");
  EXPECT_EQ(html::paragraph("text"), "<p>text</p>\n");
}

TEST(Html, TablesImagesLinksAndNumbers) {
  EXPECT_EQ(html::tableStart({"set", "loss"}), "<table><tr><th>set</th><th>loss</th></tr>\n");
  EXPECT_EQ(html::labelledRow("a", {"1", ""}),
            "<tr><td style='text-align:left'>a</td><td>1</td><td></td></tr>\n");
  EXPECT_EQ(html::labelledRow("only", {}), "<tr><td style='text-align:left'>only</td></tr>\n");
  EXPECT_EQ(html::tableEnd(), "</table>\n");
  EXPECT_EQ(html::image("a.svg", "plot"), "<img src='a.svg' alt='plot'>");
  EXPECT_EQ(html::link("r.csv", "data"), "<a href='r.csv'>data</a>");
  EXPECT_EQ(html::number(0.12345, "%.3f"), "0.123");
  EXPECT_EQ(html::number(1234567.0, "%.6g"), "1.23457e+06");
}

}  // namespace
}  // namespace paircast

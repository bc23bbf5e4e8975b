// The scaffolding that paircast's offline HTML reports share (dataset_report's report.html,
// covis_sweep's summary.html): the page's head and styles, tables of numbers with a label in the
// first column, images, links and paragraphs. Every function returns markup to append; none
// escapes its arguments, so text that may hold markup goes through plot::escape first.
#pragma once

#include <string>
#include <vector>

namespace paircast::html {

// A <style> block: the body in a sans-serif font at most `maxWidthPx` wide, tables with ruled
// cells, numbers right-aligned and shaded headers; then `extraRules`, the page's own.
std::string style(int maxWidthPx, const std::string& extraRules = "");
// The page up to and including <body> and a line break: the doctype, then a head holding the
// title (already escaped) and `head` (a style() block, with whatever should come before it).
std::string pageStart(const std::string& title, const std::string& head);
// Closes what pageStart opened, and ends the file with a line break.
std::string pageEnd();

// A heading of `level` (1 for <h1>) on a line of its own.
std::string heading(int level, const std::string& text);
// A paragraph on a line of its own.
std::string paragraph(const std::string& text);
// <img src='src' alt='alt'>
std::string image(const std::string& src, const std::string& alt);
// <a href='href'>text</a>
std::string link(const std::string& href, const std::string& text);

// A table's opening tag and its header row.
std::string tableStart(const std::vector<std::string>& headers);
// A row whose first cell, `label`, is aligned left; the other cells stay right-aligned (numbers).
std::string labelledRow(const std::string& label, const std::vector<std::string>& cells);
// Closes a table.
std::string tableEnd();

// A number for a cell, printf-formatted (e.g. "%.3f", "%.6g").
std::string number(double value, const char* format);

}  // namespace paircast::html

#include "util/html.h"

#include <cstdio>

namespace paircast::html {

std::string style(int maxWidthPx, const std::string& extraRules) {
  return "<style>body{font-family:sans-serif;margin:24px;max-width:" + std::to_string(maxWidthPx) +
         "px}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:"
         "right}th{background:#f3f3f3}" +
         extraRules + "</style>";
}

std::string pageStart(const std::string& title, const std::string& head) {
  return "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>" + title +
         "</title>" + head + "</head><body>\n";
}

std::string pageEnd() {
  return "</body></html>\n";
}

std::string heading(int level, const std::string& text) {
  const std::string tag = "h" + std::to_string(level);
  return "<" + tag + ">" + text + "</" + tag + ">\n";
}

std::string paragraph(const std::string& text) {
  return "<p>" + text + "</p>\n";
}

std::string image(const std::string& src, const std::string& alt) {
  return "<img src='" + src + "' alt='" + alt + "'>";
}

std::string link(const std::string& href, const std::string& text) {
  return "<a href='" + href + "'>" + text + "</a>";
}

std::string tableStart(const std::vector<std::string>& headers) {
  std::string s = "<table><tr>";
  for (const auto& h : headers) s += "<th>" + h + "</th>";
  return s + "</tr>\n";
}

std::string labelledRow(const std::string& label, const std::vector<std::string>& cells) {
  std::string s = "<tr><td style='text-align:left'>" + label + "</td>";
  for (const auto& c : cells) s += "<td>" + c + "</td>";
  return s + "</tr>\n";
}

std::string tableEnd() {
  return "</table>\n";
}

std::string number(double value, const char* format) {
  char b[64];
  std::snprintf(b, sizeof b, format, value);
  return b;
}

}  // namespace paircast::html

#include "client/report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "nlohmann/json.hpp"
#include "solver/geometry/vec.h"

namespace radiosity::client {

namespace {

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string Number(double v) { return absl::StrFormat("%.4g", v); }

}  // namespace

std::string SensorGridStats::ToString() const {
  return absl::StrFormat("%s: %d points, min %.6g mean %.6g max %.6g U0 %.4f min/max %.4f", name,
                         points, min, mean, max, u0, min_max);
}

absl::StatusOr<std::vector<SensorGridStats>> SensorStatsFromCsv(const std::string& csv) {
  std::vector<std::string> lines = absl::StrSplit(csv, '\n', absl::SkipWhitespace());
  if (lines.empty()) return absl::InvalidArgumentError("sensors.csv: empty");
  const std::vector<std::string> header = absl::StrSplit(absl::StripSuffix(lines[0], "\r"), ',');
  auto column = [&](const std::string& name) {
    auto it = std::find(header.begin(), header.end(), name);
    return it == header.end() ? -1 : static_cast<int>(it - header.begin());
  };
  const int r = column("r"), g = column("g"), b = column("b"), grid = column("grid");
  if (r < 0 || g < 0 || b < 0) {
    return absl::InvalidArgumentError("sensors.csv:1: no r, g, b columns");
  }
  std::vector<SensorGridStats> grids;
  std::map<std::string, size_t> index;
  std::vector<double> sums;
  for (size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> cells = absl::StrSplit(absl::StripSuffix(lines[i], "\r"), ',');
    Rgb e;
    if (cells.size() != header.size() || !absl::SimpleAtod(cells[r], &e.r) ||
        !absl::SimpleAtod(cells[g], &e.g) || !absl::SimpleAtod(cells[b], &e.b)) {
      return absl::InvalidArgumentError(
          absl::StrCat("sensors.csv:", i + 1, ": not a row of ", header.size(), " values"));
    }
    const std::string name = grid >= 0 ? cells[grid] : "all";
    auto [it, inserted] = index.emplace(name, grids.size());
    if (inserted) {
      grids.push_back({name, 0, std::numeric_limits<double>::infinity(), 0,
                       -std::numeric_limits<double>::infinity()});
      sums.push_back(0);
    }
    SensorGridStats& s = grids[it->second];
    const double y = e.Luminance();
    s.points += 1;
    s.min = std::min(s.min, y);
    s.max = std::max(s.max, y);
    sums[it->second] += y;
  }
  for (size_t k = 0; k < grids.size(); ++k) {
    SensorGridStats& s = grids[k];
    s.mean = sums[k] / s.points;
    s.u0 = s.mean > 0 ? s.min / s.mean : 0;
    s.min_max = s.max > 0 ? s.min / s.max : 0;
  }
  return grids;
}

std::string ConvergenceSvg(const std::vector<double>& seconds,
                           const std::vector<double>& unshot_fraction, double tolerance,
                           const std::vector<double>& std_error) {
  constexpr int kW = 640, kH = 360, kLeft = 70, kRight = 20, kTop = 20, kBottom = 50;
  std::string svg = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" "
      "font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%%\" height=\"100%%\" "
      "fill=\"white\"/>\n",
      kW, kH);
  const size_t n = std::min(seconds.size(), unshot_fraction.size());
  double t_max = 0, lo = tolerance > 0 ? tolerance : 1, hi = 1;
  for (size_t i = 0; i < n; ++i) {
    t_max = std::max(t_max, seconds[i]);
    if (unshot_fraction[i] > 0) {
      lo = std::min(lo, unshot_fraction[i]);
      hi = std::max(hi, unshot_fraction[i]);
    }
    if (i < std_error.size() && std_error[i] > 0) {
      lo = std::min(lo, std_error[i]);
      hi = std::max(hi, std_error[i]);
    }
  }
  if (n == 0) {
    absl::StrAppend(&svg, "<text x=\"", kW / 2, "\" y=\"", kH / 2,
                    "\" text-anchor=\"middle\">no convergence history</text>\n</svg>\n");
    return svg;
  }
  if (!(t_max > 0)) t_max = 1;
  const double e_lo = std::floor(std::log10(lo)), e_hi = std::ceil(std::log10(hi));
  const double decades = std::max(1.0, e_hi - e_lo);
  auto x = [&](double t) { return kLeft + (kW - kLeft - kRight) * t / t_max; };
  auto y = [&](double u) {
    const double v = std::log10(std::max(u, std::pow(10.0, e_lo)));
    return kTop + (kH - kTop - kBottom) * (e_hi - v) / decades;
  };
  // Axes, decade grid lines and labels.
  for (double e = e_lo; e <= e_lo + decades + 1e-9; e += 1) {
    const double yy = y(std::pow(10.0, e));
    absl::StrAppendFormat(&svg,
                          "<line x1=\"%d\" y1=\"%.1f\" x2=\"%d\" y2=\"%.1f\" stroke=\"#ddd\"/>"
                          "<text x=\"%d\" y=\"%.1f\" text-anchor=\"end\">1e%d</text>\n",
                          kLeft, yy, kW - kRight, yy, kLeft - 6, yy + 4, static_cast<int>(e));
  }
  for (int k = 0; k <= 4; ++k) {
    const double t = t_max * k / 4;
    absl::StrAppendFormat(&svg, "<text x=\"%.1f\" y=\"%d\" text-anchor=\"middle\">%s</text>\n",
                          x(t), kH - kBottom + 18, Number(t));
  }
  absl::StrAppendFormat(&svg,
                        "<text x=\"%d\" y=\"%d\" text-anchor=\"middle\">seconds</text>\n"
                        "<text x=\"14\" y=\"%d\" transform=\"rotate(-90 14 %d)\" "
                        "text-anchor=\"middle\">fraction</text>\n",
                        (kLeft + kW - kRight) / 2, kH - 10, kH / 2, kH / 2);
  absl::StrAppendFormat(&svg,
                        "<rect x=\"%d\" y=\"%d\" width=\"%d\" height=\"%d\" fill=\"none\" "
                        "stroke=\"#444\"/>\n",
                        kLeft, kTop, kW - kLeft - kRight, kH - kTop - kBottom);
  if (tolerance > 0) {
    absl::StrAppendFormat(&svg,
                          "<line class=\"tolerance\" x1=\"%d\" y1=\"%.1f\" x2=\"%d\" y2=\"%.1f\" "
                          "stroke=\"#c33\" stroke-dasharray=\"6 4\"/>\n",
                          kLeft, y(tolerance), kW - kRight, y(tolerance));
  }
  std::vector<std::string> points;
  for (size_t i = 0; i < n; ++i) {
    points.push_back(absl::StrFormat("%.1f,%.1f", x(seconds[i]), y(unshot_fraction[i])));
  }
  absl::StrAppend(&svg,
                  "<polyline class=\"convergence\" fill=\"none\" stroke=\"#26828e\" "
                  "stroke-width=\"2\" points=\"",
                  absl::StrJoin(points, " "), "\"/>\n");
  // The estimated relative error where it was measured (snapshots and the end).
  std::vector<std::string> error_points;
  for (size_t i = 0; i < n && i < std_error.size(); ++i) {
    if (std_error[i] > 0) {
      error_points.push_back(absl::StrFormat("%.1f,%.1f", x(seconds[i]), y(std_error[i])));
    }
  }
  absl::StrAppendFormat(&svg, "<text x=\"%d\" y=\"%d\" fill=\"#26828e\">unshot fraction</text>\n",
                        kLeft + 10, kTop + 16);
  if (!error_points.empty()) {
    absl::StrAppend(&svg,
                    "<polyline class=\"error\" fill=\"none\" stroke=\"#b5651d\" "
                    "stroke-width=\"2\" stroke-dasharray=\"2 3\" points=\"",
                    absl::StrJoin(error_points, " "), "\"/>\n");
    absl::StrAppendFormat(&svg,
                          "<text x=\"%d\" y=\"%d\" fill=\"#b5651d\">estimated relative "
                          "error (RMS standard error)</text>\n",
                          kLeft + 10, kTop + 32);
  }
  absl::StrAppend(&svg, "</svg>\n");
  return svg;
}

absl::StatusOr<std::string> ReportHtml(const std::string& job, const std::string& summary_json,
                                       const std::string& image,
                                       const std::vector<SensorGridStats>& grids) {
  const nlohmann::json s = nlohmann::json::parse(summary_json, nullptr, false);
  if (s.is_discarded() || !s.is_object()) {
    return absl::InvalidArgumentError("summary.json: not a JSON object");
  }
  auto text = [&](const char* key) -> std::string {
    if (!s.contains(key)) return "";
    const nlohmann::json& v = s[key];
    return v.is_string()   ? v.get<std::string>()
           : v.is_number() ? Number(v.get<double>())
                           : v.dump();
  };
  auto numbers = [&](const nlohmann::json& v) {
    std::vector<double> out;
    if (v.is_array()) {
      for (const auto& x : v) out.push_back(x.is_number() ? x.get<double>() : 0);
    }
    return out;
  };
  std::vector<double> seconds, unshot, error;
  if (s.contains("convergence") && s["convergence"].is_object()) {
    seconds = numbers(s["convergence"].value("seconds", nlohmann::json::array()));
    unshot = numbers(s["convergence"].value("unshot_fraction", nlohmann::json::array()));
    // null where no error was measured: 0, which the plot skips.
    error = numbers(s["convergence"].value("std_error_rms_relative", nlohmann::json::array()));
  }
  const double tolerance = s.value("tolerance", 0.0);

  std::string html = absl::StrCat(
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>radiosity report: ", Escape(job),
      "</title>\n<style>body{font-family:sans-serif;max-width:960px;margin:2em auto}"
      "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;"
      "text-align:right}th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}"
      "</style></head><body>\n<h1>",
      Escape(job), "</h1>\n<p>Scene <code>", Escape(text("scene")),
      "</code>: ", Escape(text("method")), " (", Escape(text("method_reason")), "), ",
      Escape(text("elements")), " elements, ", Escape(text("rays")), " rays in ",
      Escape(text("seconds")), " s; stopped: ", Escape(text("stop_reason")), ".</p>\n");
  if (!image.empty()) {
    absl::StrAppend(&html, "<h2>Image</h2>\n<img src=\"", Escape(image),
                    "\" alt=\"rendered solution\" style=\"max-width:100%\">\n");
  }
  absl::StrAppend(&html, "<h2>Convergence</h2>\n",
                  ConvergenceSvg(seconds, unshot, tolerance, error), "<p>Final unshot fraction ",
                  Escape(text("unshot_fraction")), " (tolerance ", Escape(text("tolerance")),
                  "); estimated relative standard error (RMS) ",
                  Escape(text("std_error_rms_relative")), ".</p>\n");
  absl::StrAppend(&html,
                  "<h2>Energy books</h2>\n<table id=\"books\"><tr><th>power (W)</th><th>r</th>"
                  "<th>g</th><th>b</th></tr>\n");
  for (const char* key : {"emitted_power", "absorbed_power", "escaped_power", "unshot_power"}) {
    const std::vector<double> v = s.contains(key) ? numbers(s[key]) : std::vector<double>{};
    absl::StrAppend(&html, "<tr><td>", absl::StripSuffix(key, "_power"), "</td>");
    for (size_t c = 0; c < 3; ++c) {
      absl::StrAppend(&html, "<td>", c < v.size() ? Number(v[c]) : "", "</td>");
    }
    absl::StrAppend(&html, "</tr>\n");
  }
  absl::StrAppend(&html,
                  "</table>\n<p>Balance error (emitted - absorbed - escaped - unshot) / "
                  "emitted: ",
                  Escape(text("energy_balance_error")), ".</p>\n");
  if (!grids.empty()) {
    absl::StrAppend(&html, "<h2>Sensor points</h2>\n<p>",
                    s.contains("luminaires")
                        ? "Illuminance in lux (luminance-weighted; the job's luminaires give "
                          "candela, and the scene is taken to be in metres)."
                        : "Luminance-weighted irradiance, W per square scene unit.",
                    "</p>\n<table id=\"sensors\"><tr><th>grid</th><th>points</th>"
                    "<th>E<sub>min</sub></th><th>E<sub>avg</sub></th><th>E<sub>max</sub></th>"
                    "<th>U<sub>0</sub> = E<sub>min</sub>/E<sub>avg</sub></th>"
                    "<th>E<sub>min</sub>/E<sub>max</sub></th></tr>\n");
    for (const SensorGridStats& g : grids) {
      absl::StrAppend(&html, "<tr><td>", Escape(g.name), "</td><td>", g.points, "</td><td>",
                      Number(g.min), "</td><td>", Number(g.mean), "</td><td>", Number(g.max),
                      "</td><td>", absl::StrFormat("%.3f", g.u0), "</td><td>",
                      absl::StrFormat("%.3f", g.min_max), "</td></tr>\n");
    }
    absl::StrAppend(&html, "</table>\n");
  }
  absl::StrAppend(&html, "</body></html>\n");
  return html;
}

}  // namespace radiosity::client

// bench/REPORT.md and its plots from the CSVs of bench/results (bench_util.h WriteReport).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <sstream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "bench/bench_util.h"

namespace radiosity::bench {

namespace {

namespace fs = std::filesystem;

// The benchmark suites, in report order, with what they are.
struct SuiteInfo {
  const char* name;
  const char* title;
};
constexpr SuiteInfo kSuites[] = {
    {"cornell_1k", "Cornell box, about 1 k elements"},
    {"cornell_10k", "Cornell box, about 10 k elements"},
    {"cornell_100k", "Cornell box, about 100 k elements"},
    {"cornell_1m", "Cornell box, about 10^6 elements (error from two seeds)"},
    {"furnace", "Furnace (closed box, rho = 0.5, E = 1; closed form B = 2)"},
    {"room", "Occluded room (two halves joined by a doorway, light in one half)"},
};

// Series (method/estimator) in legend order, with gnuplot line styles.
struct SeriesStyle {
  const char* key;
  const char* color;
  int dash;
  int point;
};
constexpr SeriesStyle kStyles[] = {
    {"progressive/montecarlo", "#1f77b4", 1, 7},  {"reflection/montecarlo", "#9467bd", 1, 5},
    {"gauss-seidel/montecarlo", "#2ca02c", 1, 9}, {"jacobi/montecarlo", "#2ca02c", 2, 8},
    {"gauss-seidel/analytic", "#d62728", 1, 11},  {"jacobi/analytic", "#d62728", 2, 10},
    {"gauss-seidel/hemicube", "#ff7f0e", 1, 13},  {"jacobi/hemicube", "#ff7f0e", 2, 12},
};

double Num(const std::string& s) {
  double v = NAN;
  if (!absl::SimpleAtod(s, &v)) return NAN;
  return v;
}

std::string Fmt(double v, const char* fmt = "%.3g") {
  if (!std::isfinite(v)) return "-";
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}
std::string Pct(double v) {
  if (!std::isfinite(v)) return "-";
  if (v != 0 && std::fabs(v) < 0.001) return absl::StrFormat("%.2g %%", 100 * v);
  return absl::StrFormat(v < 0.01 ? "%.2f %%" : "%.1f %%", 100 * v);
}
std::string Seconds(double s) {
  if (!std::isfinite(s)) return "-";
  if (s < 0.1) return absl::StrFormat("%.3f s", s);
  if (s < 10) return absl::StrFormat("%.2f s", s);
  if (s < 1000) return absl::StrFormat("%.0f s", s);
  return absl::StrFormat("%.0f min", s / 60);
}

// One point of a series: the mean over seeds at one budget.
struct Point {
  std::string budget;
  double wall = 0, cpu = 0, rays = 0, rms = 0, p99 = 0, max = 0, power = 0, balance = 0;
  double peak = 0, noise = 0, load = 0;
  int count = 0;
  // RMS error with the reference's own noise removed in quadrature (at most a factor 3):
  // E[measured^2] = true^2 + noise^2 for independent errors.
  double Corrected() const {
    const double c2 = rms * rms - noise * noise;
    return std::max(std::sqrt(std::max(c2, 0.0)), rms / 3);
  }
};

struct Series {
  std::string key;            // method/estimator
  std::vector<Point> points;  // In the CSV's (budget) order.
};

struct Suite {
  std::string name;
  int64_t elements = 0;
  double noise = 0;
  std::vector<Series> series;
  const Series* Find(const std::string& key) const {
    for (const Series& s : series) {
      if (s.key == key) return &s;
    }
    return nullptr;
  }
};

absl::StatusOr<Suite> LoadSuite(const std::string& path, const std::string& name) {
  absl::StatusOr<Table> t = ReadTable(path);
  if (!t.ok()) return t.status();
  Suite suite;
  suite.name = name;
  auto col = [&](const char* c) { return t->Column(c); };
  const int c_method = col("method"), c_est = col("estimator"), c_budget = col("budget"),
            c_wall = col("wall_s"), c_cpu = col("cpu_s"), c_rays = col("rays"),
            c_rms = col("rms_lum"), c_p99 = col("p99_lum"), c_max = col("max_lum"),
            c_power = col("power_error"), c_bal = col("balance_error"),
            c_peak = col("peak_rss_mib"), c_noise = col("ref_noise"), c_n = col("elements"),
            c_load = col("load");
  if (c_method < 0 || c_rms < 0 || c_wall < 0) {
    return absl::DataLossError(absl::StrCat(path, ": not a results CSV"));
  }
  for (const auto& row : t->rows) {
    const std::string key = row[c_method] + "/" + row[c_est];
    Series* series = nullptr;
    for (Series& s : suite.series) {
      if (s.key == key) series = &s;
    }
    if (series == nullptr) {
      suite.series.push_back({key, {}});
      series = &suite.series.back();
    }
    Point* p = nullptr;
    for (Point& q : series->points) {
      if (q.budget == row[c_budget]) p = &q;
    }
    if (p == nullptr) {
      series->points.push_back(Point{});
      p = &series->points.back();
      p->budget = row[c_budget];
    }
    p->wall += Num(row[c_wall]);
    p->cpu += Num(row[c_cpu]);
    p->rays += Num(row[c_rays]);
    p->rms += Num(row[c_rms]);
    p->p99 += Num(row[c_p99]);
    p->max += Num(row[c_max]);
    p->power += Num(row[c_power]);
    p->balance += Num(row[c_bal]);
    p->peak = std::max(p->peak, Num(row[c_peak]));
    p->noise = Num(row[c_noise]);
    if (!std::isfinite(p->noise)) p->noise = 0;  // "unknown" or "nan": no correction.
    p->load = std::max(p->load, Num(row[c_load]));
    p->count += 1;
    suite.elements = static_cast<int64_t>(Num(row[c_n]));
    if (std::isfinite(p->noise)) suite.noise = p->noise;
  }
  for (Series& s : suite.series) {
    for (Point& p : s.points) {
      const double k = p.count;
      p.wall /= k;
      p.cpu /= k;
      p.rays /= k;
      p.rms /= k;
      p.p99 /= k;
      p.max /= k;
      p.power /= k;
      p.balance /= k;
    }
  }
  // Legend order.
  std::stable_sort(suite.series.begin(), suite.series.end(), [](const Series& a, const Series& b) {
    auto rank = [](const std::string& k) {
      for (size_t i = 0; i < std::size(kStyles); ++i) {
        if (k == kStyles[i].key) return static_cast<int>(i);
      }
      return 100;
    };
    return rank(a.key) < rank(b.key);
  });
  return suite;
}

// Least-squares slope of log y against log x.
double LogSlope(const std::vector<std::pair<double, double>>& xy) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (const auto& [x, y] : xy) {
    if (!(x > 0) || !(y > 0)) continue;
    const double lx = std::log(x), ly = std::log(y);
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
    ++n;
  }
  if (n < 2) return NAN;
  const double d = n * sxx - sx * sx;
  return d == 0 ? NAN : (n * sxy - sx * sy) / d;
}

// Time to reach `target` corrected RMS error along a series, interpolated linearly in
// (log time, log error) between the last point above and the first point at or below it.
struct Reach {
  double seconds = NAN;
  bool reached = false;
  bool at_first = false;      // Already below at the cheapest budget: an upper bound.
  double extrapolated = NAN;  // Not reached: where the last two points' trend would reach it.
};

Reach TimeToReach(const Series& s, double target) {
  std::vector<const Point*> pts;
  for (const Point& p : s.points) {
    if (std::isfinite(p.rms) && p.rms > 0 && p.wall > 0) pts.push_back(&p);
  }
  std::sort(pts.begin(), pts.end(),
            [](const Point* a, const Point* b) { return a->wall < b->wall; });
  Reach r;
  for (size_t k = 0; k < pts.size(); ++k) {
    if (pts[k]->Corrected() > target) continue;
    r.reached = true;
    if (k == 0) {
      r.at_first = true;
      r.seconds = pts[0]->wall;
      return r;
    }
    const double x0 = std::log(pts[k - 1]->wall), x1 = std::log(pts[k]->wall);
    const double y0 = std::log(pts[k - 1]->Corrected()), y1 = std::log(pts[k]->Corrected());
    const double y = std::log(target);
    r.seconds = y1 == y0 ? pts[k]->wall : std::exp(x0 + (y - y0) * (x1 - x0) / (y1 - y0));
    return r;
  }
  // Not reached: extrapolate the trend of the last three points (two are too noisy to trust).
  if (pts.size() >= 3) {
    std::vector<std::pair<double, double>> tail;
    for (size_t k = pts.size() - 3; k < pts.size(); ++k) {
      tail.push_back({pts[k]->wall, pts[k]->Corrected()});
    }
    double slope = LogSlope(tail);
    const Point* b = pts.back();
    if (slope < -0.2) r.extrapolated = b->wall * std::pow(target / b->Corrected(), 1 / slope);
  }
  return r;
}

std::string ReachText(const Reach& r) {
  if (r.reached) return (r.at_first ? "<= " : "") + Seconds(r.seconds);
  if (std::isfinite(r.extrapolated))
    return absl::StrCat("not reached (~", Seconds(r.extrapolated), " extrap.)");
  return "not reached";
}

// Convergence order of a series: slope of log(corrected error) against log(time) over the points
// whose error is clearly above the reference's noise.
double ConvergenceSlope(const Series& s) {
  std::vector<std::pair<double, double>> xy;
  for (const Point& p : s.points) {
    if (p.rms > 3 * p.noise) xy.push_back({p.wall, p.Corrected()});
  }
  return xy.size() >= 3 ? LogSlope(xy) : NAN;
}

std::map<std::string, std::string> ReadKeyValues(const std::string& path) {
  std::map<std::string, std::string> kv;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    const size_t c = line.find(':');
    if (c == std::string::npos) continue;
    std::string v = line.substr(c + 1);
    while (!v.empty() && v[0] == ' ') v.erase(0, 1);
    kv[line.substr(0, c)] = v;
  }
  return kv;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '\'')
      out += "''";
    else
      out += c;
  }
  return out;
}

const SeriesStyle* StyleOf(const std::string& key) {
  for (const SeriesStyle& st : kStyles) {
    if (key == st.key) return &st;
  }
  return nullptr;
}

// Writes the data and gnuplot script for a suite's error-against-time plot and runs gnuplot.
absl::Status PlotSuite(const ReportOptions& o, const Suite& suite, const std::string& title) {
  const std::string dat = o.results_dir + "/plot_" + suite.name + ".dat";
  const std::string gp = o.results_dir + "/plot_" + suite.name + ".gp";
  std::ofstream d(dat);
  int index = 0;
  std::vector<std::string> plots;
  for (const Series& s : suite.series) {
    std::vector<const Point*> pts;
    for (const Point& p : s.points) {
      if (std::isfinite(p.rms) && p.rms > 0 && p.wall > 0) pts.push_back(&p);
    }
    if (pts.empty()) continue;
    std::sort(pts.begin(), pts.end(),
              [](const Point* a, const Point* b) { return a->wall < b->wall; });
    d << "# " << s.key << "\n";
    for (const Point* p : pts) {
      d << absl::StrFormat("%.6g %.6g %s\n", p->wall, p->rms, p->budget);
    }
    d << "\n\n";
    const SeriesStyle* st = StyleOf(s.key);
    plots.push_back(absl::StrFormat(
        "'%s' index %d using 1:2 with linespoints lw 2 ps 1.1 lc rgb '%s' dt %d pt %d title '%s'",
        Escape(dat), index, st ? st->color : "#444444", st ? st->dash : 1, st ? st->point : 6,
        s.key));
    if (s.key == "progressive/montecarlo" || s.key == "gauss-seidel/hemicube" ||
        s.key == "gauss-seidel/analytic") {
      // Label the budgets of the main series.
      plots.push_back(absl::StrFormat(
          "'%s' index %d using 1:2:3 with labels offset 0.6,0.6 font ',7' tc rgb '%s' notitle",
          Escape(dat), index, st ? st->color : "#444444"));
    }
    ++index;
  }
  d.close();
  if (plots.empty()) return absl::OkStatus();
  std::ofstream g(gp);
  g << "set terminal pngcairo size 960,600 enhanced font 'Sans,10'\n";
  g << "set output '" << Escape(o.figures_dir + "/" + suite.name + ".png") << "'\n";
  g << "set title '" << Escape(title) << absl::StrFormat(" (N = %d)", suite.elements) << "'\n";
  g << "set logscale xy\nset grid xtics ytics mxtics mytics lc rgb '#dddddd'\n";
  g << "set xlabel 'wall time of the solve (s, 2 threads)'\n";
  g << "set ylabel 'RMS relative error of element radiosity (luminance, area-weighted)'\n";
  g << "set format y '%g'\nset format x '%g'\n";
  g << "set key outside right top box\n";
  g << "set yrange [*:*]\n";
  std::string extra =
      ", 0.1 with lines lc rgb '#999999' dt 3 notitle, 0.03 with lines lc rgb '#999999' dt 3 "
      "notitle, 0.01 with lines lc rgb '#999999' dt 3 title '10 %, 3 %, 1 %'";
  if (suite.noise > 0) {
    extra += absl::StrFormat(", %g with lines lc rgb '#000000' dt 4 title 'reference noise'",
                             suite.noise);
  }
  g << "plot " << absl::StrJoin(plots, ", \\\n     ") << extra << "\n";
  g.close();
  const std::string cmd = absl::StrCat(o.gnuplot, " '", gp, "' 2>&1");
  if (std::system(cmd.c_str()) != 0) {
    return absl::InternalError(absl::StrCat("gnuplot failed on ", gp));
  }
  return absl::OkStatus();
}

struct ClaimPoint {
  double n;
  double error;  // RMS, corrected for the reference's noise.
  std::string source;
};

// ---------------------------------------------------------------------------------------------
// Adaptive and hierarchical against uniform meshes (issue 7), from meshes.csv
// (radiosity_bench meshes).

struct MeshRow {
  std::string suite, variant, budget;
  double max_elements = 0, elements = 0, pieces = 0, passes = 0, wall = 0, rays = 0, links = 0;
  double link_mib = 0, peak = 0, base = 0, l2 = 0, l2i = 0, rms = 0, noise = 0, ref_elements = 0;
  double load = 0;
  std::string Config() const {
    if (variant == "hierarchical") {
      return absl::StrFormat("%.0f leaves, tolerance %s", elements, budget);
    }
    if (variant.rfind("adaptive", 0) == 0) {
      return absl::StrFormat("budget %.0f, %s rays/element, %.0f passes", max_elements, budget,
                             passes);
    }
    return absl::StrFormat("%s rays/element", budget);
  }
  // The elements the solution really has: the hierarchical receivers, or the mesh's elements.
  double Used() const { return variant == "hierarchical" ? pieces : elements; }
  double Memory() const { return std::max(0.0, peak - base); }
};

constexpr struct {
  const char* suite;
  const char* title;
} kMeshSuites[] = {{"meshes_cornell", "Cornell box"},
                   {"meshes_room", "Occluded room"},
                   {"meshes_furnace", "Furnace (closed form B = 2)"}};
constexpr const char* kVariants[] = {"uniform", "adaptive", "adaptive-resolve", "hierarchical"};
constexpr const char* kVariantColors[] = {"#1f77b4", "#d62728", "#ff7f0e", "#2ca02c"};

void AppendMeshesSection(const ReportOptions& o, std::string* md) {
  absl::StatusOr<Table> t = ReadTable(o.results_dir + "/meshes.csv");
  if (!t.ok() || t->rows.empty()) return;
  std::vector<MeshRow> rows;
  for (const auto& r : t->rows) {
    auto col = [&](const char* name) {
      const int c = t->Column(name);
      return c >= 0 ? r[c] : std::string();
    };
    MeshRow m;
    m.suite = col("suite");
    m.variant = col("variant");
    m.budget = col("budget");
    m.max_elements = Num(col("max_elements"));
    m.elements = Num(col("elements"));
    m.pieces = Num(col("pieces"));
    m.passes = Num(col("passes"));
    m.wall = Num(col("wall_s"));
    m.rays = Num(col("rays"));
    m.links = Num(col("links"));
    m.link_mib = Num(col("link_mib"));
    m.peak = Num(col("peak_rss_mib"));
    m.base = Num(col("base_rss_mib"));
    m.l2 = Num(col("l2_lum"));
    m.l2i = Num(col("l2_interp"));
    m.rms = Num(col("rms_lum"));
    m.noise = Num(col("ref_noise"));
    m.ref_elements = Num(col("ref_elements"));
    m.load = Num(col("load"));
    rows.push_back(m);
  }
  absl::StrAppend(md, "## Adaptive and hierarchical against uniform meshes (equal error)\n\n");
  const auto run = ReadKeyValues(o.results_dir + "/meshes_run.txt");
  if (run.count("date")) {
    absl::StrAppend(md, "Measured by `bench/run --only adaptive` (", run.at("mode"), " mode) on ",
                    run.at("date"), ", commit ", run.count("commit") ? run.at("commit") : "?",
                    "; the suite took ", run.count("seconds") ? run.at("seconds") : "?",
                    " s (1-minute load average at its end ",
                    run.count("load_end") ? run.at("load_end") : "?",
                    "; every row records the load at its start).\n\n");
  }
  absl::StrAppend(
      md,
      "Three ways to spend elements: **uniform** meshes (progressive solver, Monte Carlo), "
      "**adaptive** refinement (`radiosity solve --refine 0.1`: the same solver on a sixteenth of "
      "the element budget, then passes of split, re-mesh and re-gather, where the new elements "
      "get their direct light again by shadow rays and keep their parent's indirect light; "
      "**adaptive-resolve** is `--refine-resolve`, which solves again from scratch after every "
      "split) and "
      "**hierarchical** radiosity (`--method hierarchical` on a uniform leaf mesh; its receivers "
      "stop where the BF oracle is satisfied, so the elements it really uses, the *pieces*, are "
      "fewer than the leaves). Each ladder varies the element count and the budget (rays per "
      "element; for hierarchical the tolerance, whose tenth is the refinement epsilon). One seed "
      "per point; `radiosity_bench meshes` (bench/run `--only adaptive`).\n\n"
      "**Error on a common basis.** The meshes differ, so every solution is carried onto the "
      "stored reference's uniform mesh (the finest reference: Cornell box 99 232 elements; room "
      "and furnace as listed below): each reference element gets the area average of the "
      "solution over it, read piecewise constant (4 x 4 midpoints per element; exact where the "
      "solution's elements nest in the reference's), and compared there. The headline error is "
      "the normwise relative L2 error of luminance, sqrt(sum A (B - B_ref)^2 / sum A B_ref^2), "
      "over the reference's non-emitting element sides that it found lit (the floor under the "
      "Cornell blocks, which nothing sees, is left out). It measures the radiosity *function*: "
      "discretisation error (a coarse element cannot follow a shadow edge) plus the solver's "
      "noise and bias; detail finer than the reference's elements is not seen. The per-element "
      "relative RMS used elsewhere in this report is not usable across meshes: it divides by the "
      "near-zero radiosity of contact shadows (reference elements a coarse element straddles get "
      "errors of 100x), so it is in the CSV (`rms_lum`) but not used here. *interp.* is the same "
      "error with the solution bilinearly interpolated (as images show it). The reference's own "
      "noise (per element, in the table of references) is a floor of the measurable error.\n\n"
      "**Costs.** Time: wall seconds after the first mesh (uniform and hierarchical: the solve; "
      "adaptive: every pass, refinement, re-meshing, Embree rebuild and re-gather or re-solve "
      "included). Memory: peak "
      "resident set during the solve above the resident set before it (MiB; small solves are "
      "below the allocator's noise; the hierarchical solver's blocks are often served from memory "
      "the process freed earlier, so for it the bytes its hierarchy and links hold, counted by "
      "the solver, are the figure to read). "
      "At equal error: among the measured points of each ladder that reach the target, the "
      "fastest (its elements and memory), and the fewest elements any point needed.\n\n");
  const double targets[] = {0.10, 0.05, 0.03, 0.02};
  for (const auto& info : kMeshSuites) {
    std::vector<const MeshRow*> mine;
    for (const MeshRow& r : rows) {
      if (r.suite == info.suite && std::isfinite(r.l2)) mine.push_back(&r);
    }
    if (mine.empty()) continue;
    const std::string name = info.suite;
    absl::StrAppend(md, "### ", info.title, "\n\n");
    absl::StrAppend(md, "Reference: ", Fmt(mine[0]->ref_elements, "%.0f"), " elements, noise ",
                    Pct(mine[0]->noise), " RMS per element.\n\n");
    absl::StrAppend(md, "![", name, "](figures/", name, ".png)\n\n");
    absl::StrAppend(md,
                    "| L2 error at most | variant | fastest point | elements used | time | "
                    "memory | fewest elements reaching it |\n"
                    "| --- | --- | --- | --- | --- | --- | --- |\n");
    for (double target : targets) {
      for (const char* variant : kVariants) {
        const MeshRow* fastest = nullptr;
        const MeshRow* fewest = nullptr;
        bool any = false;
        for (const MeshRow* r : mine) {
          if (r->variant != variant) continue;
          any = true;
          if (r->l2 > target) continue;
          if (!fastest || r->wall < fastest->wall) fastest = r;
          if (!fewest || r->Used() < fewest->Used()) fewest = r;
        }
        if (!any) continue;
        if (!fastest) {
          double best = INFINITY;
          for (const MeshRow* r : mine) {
            if (r->variant == variant) best = std::min(best, r->l2);
          }
          absl::StrAppend(md, "| ", Pct(target), " | ", variant, " | not reached (best ", Pct(best),
                          ") | | | | |\n");
          continue;
        }
        std::string memory = absl::StrCat(Fmt(fastest->Memory(), "%.0f"), " MiB");
        if (fastest->variant == "hierarchical") {
          absl::StrAppend(&memory, " (links ", Fmt(fastest->link_mib, "%.1f"), " MiB, ",
                          Fmt(fastest->links, "%.3g"), " links)");
        }
        absl::StrAppend(md, "| ", Pct(target), " | ", variant, " | ", fastest->Config(), " (",
                        Pct(fastest->l2), ") | ", Fmt(fastest->Used(), "%.0f"), " | ",
                        Seconds(fastest->wall), " | ", memory, " | ", Fmt(fewest->Used(), "%.0f"),
                        " (", fewest->Config(), ") |\n");
      }
    }
    absl::StrAppend(
        md,
        "\nEvery point:\n\n| variant | max elements | elements | pieces | budget | "
        "passes | time | L2 | L2 interp. | per-element RMS | links | memory | load |\n"
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    for (const MeshRow* r : mine) {
      absl::StrAppend(md, "| ", r->variant, " | ", Fmt(r->max_elements, "%.0f"), " | ",
                      Fmt(r->elements, "%.0f"), " | ", Fmt(r->pieces, "%.0f"), " | ", r->budget,
                      " | ", Fmt(r->passes, "%.0f"), " | ", Seconds(r->wall), " | ", Pct(r->l2),
                      " | ", Pct(r->l2i), " | ", Pct(r->rms), " | ",
                      r->links > 0 ? Fmt(r->links, "%.3g") : "-", " | ", Fmt(r->Memory(), "%.0f"),
                      " MiB | ", Fmt(r->load, "%.2g"), " |\n");
    }
    absl::StrAppend(md, "\n");
    // Wireframe pictures of this scene, when bench/run made them.
    const std::string stem = name.substr(std::string("meshes_").size());
    std::vector<std::string> pictures;
    if (fs::exists(o.figures_dir)) {
      for (const auto& entry : fs::directory_iterator(o.figures_dir)) {
        const std::string f = entry.path().filename().string();
        if (f.rfind("wire_" + stem + "_", 0) == 0 && entry.path().extension() == ".png") {
          pictures.push_back(f);
        }
      }
    }
    std::sort(pictures.begin(), pictures.end());
    for (const std::string& f : pictures) {
      absl::StrAppend(md, "![", f, "](figures/", f, ") ");
    }
    if (!pictures.empty()) {
      absl::StrAppend(md, "\n\n", pictures.size() > 1 ? "Wireframes" : "Wireframe",
                      " over the shaded solution (`radiosity_bench meshes --png`, "
                      "DrawWireframe): ",
                      absl::StrJoin(pictures, ", "),
                      " (wire_SCENE_VARIANT_N.png; for hierarchical the lines bound its receiver "
                      "pieces, not its leaves).\n\n");
    }

    // Figure: error against elements used and against time, one colour per variant, the
    // points joined along each variant's lower envelope (Pareto front) in time.
    const std::string dat = o.results_dir + "/plot_" + name + ".dat";
    const std::string gp = o.results_dir + "/plot_" + name + ".gp";
    std::ofstream d(dat);
    std::vector<std::string> by_n, by_t;
    int index = 0;
    for (int v = 0; v < static_cast<int>(std::size(kVariants)); ++v) {
      std::vector<const MeshRow*> pts;
      for (const MeshRow* r : mine) {
        if (r->variant == kVariants[v] && r->l2 > 0 && r->wall > 0) pts.push_back(r);
      }
      if (pts.empty()) continue;
      d << "# " << kVariants[v] << ": used elements, time, L2, label\n";
      for (const MeshRow* r : pts) {
        d << absl::StrFormat("%.6g %.6g %.6g %s\n", r->Used(), r->wall, r->l2, r->budget);
      }
      d << "\n\n";
      // The lower envelope in time: points sorted by time whose error beats every faster one.
      std::sort(pts.begin(), pts.end(),
                [](const MeshRow* a, const MeshRow* b) { return a->wall < b->wall; });
      d << "# " << kVariants[v] << ": fastest to each error\n";
      double best = INFINITY;
      for (const MeshRow* r : pts) {
        if (r->l2 < best) {
          best = r->l2;
          d << absl::StrFormat("%.6g %.6g %.6g %s\n", r->Used(), r->wall, r->l2, r->budget);
        }
      }
      d << "\n\n";
      by_n.push_back(absl::StrFormat(
          "'%s' index %d using 1:3 with points pt 7 ps 1.2 lc rgb '%s' title '%s', "
          "'%s' index %d using 1:3:4 with labels offset 0.5,0.5 font ',7' tc rgb '%s' notitle",
          Escape(dat), index, kVariantColors[v], kVariants[v], Escape(dat), index,
          kVariantColors[v]));
      by_t.push_back(
          absl::StrFormat("'%s' index %d using 2:3 with points pt 7 ps 1.2 lc rgb '%s' title '%s', "
                          "'%s' index %d using 2:3 with lines lw 2 lc rgb '%s' notitle",
                          Escape(dat), index, kVariantColors[v], kVariants[v], Escape(dat),
                          index + 1, kVariantColors[v]));
      index += 2;
    }
    d.close();
    std::ofstream g(gp);
    g << "set terminal pngcairo size 1100,460 enhanced font 'Sans,10'\n";
    g << "set output '" << Escape(o.figures_dir + "/" + name + ".png") << "'\n";
    g << "set multiplot layout 1,2 title '" << Escape(info.title)
      << ": normwise L2 error on the reference mesh'\n";
    g << "set logscale xy\nset grid xtics ytics mxtics mytics lc rgb '#dddddd'\n";
    g << "set format x '%g'\nset format y '%g'\nset key top right\n";
    g << "set ylabel 'relative L2 error of luminance'\n";
    const std::string lines =
        ", 0.05 with lines lc rgb '#999999' dt 3 notitle, 0.02 with lines lc rgb '#999999' dt 3 "
        "title '5 %, 2 %'";
    g << "set xlabel 'elements used (hierarchical: receiver pieces)'\n";
    g << "set title 'against elements (labels: budget)'\n";
    g << "plot " << absl::StrJoin(by_n, ", \\\n     ") << lines << "\n";
    g << "set xlabel 'wall time (s, 2 threads)'\n";
    g << "set title 'against time (lines: fastest to each error)'\n";
    g << "plot " << absl::StrJoin(by_t, ", \\\n     ") << lines << "\n";
    g << "unset multiplot\n";
    g.close();
    std::system(absl::StrCat(o.gnuplot, " '", gp, "' >/dev/null 2>&1").c_str());
  }
}

}  // namespace

// ---- High reflectance (radiosity_bench high_rho; bench/results/high_rho.csv).

struct HighRhoPoint {
  double budget = 0, wall = 0, rays = 0, predicted = NAN, rms = NAN, max = NAN, exitant = NAN;
  double load = 0;
  bool converged = false;
  std::string stop;
};

// Time to reach `target` max element error along a ladder of converged solves, interpolated in
// (log time, log error); extrapolated along the last three points' trend when not reached.
std::string HighRhoCell(const std::vector<HighRhoPoint>& points, double target) {
  std::vector<const HighRhoPoint*> pts;
  for (const HighRhoPoint& p : points) {
    if (p.converged && p.max > 0 && p.wall > 0) pts.push_back(&p);
  }
  if (pts.empty()) {
    if (points.empty()) return "-";
    const HighRhoPoint& p = points.front();
    return absl::StrFormat("not converged (%s after %s, %s rays; max error %s)", p.stop,
                           Seconds(p.wall), Fmt(p.rays, "%.2g"), Pct(p.max));
  }
  std::sort(pts.begin(), pts.end(),
            [](const HighRhoPoint* a, const HighRhoPoint* b) { return a->wall < b->wall; });
  for (size_t k = 0; k < pts.size(); ++k) {
    if (pts[k]->max > target) continue;
    if (k == 0) return "<= " + Seconds(pts[0]->wall);
    const double x0 = std::log(pts[k - 1]->wall), x1 = std::log(pts[k]->wall);
    const double y0 = std::log(pts[k - 1]->max), y1 = std::log(pts[k]->max);
    const double y = std::log(target);
    return Seconds(y1 == y0 ? pts[k]->wall : std::exp(x0 + (y - y0) * (x1 - x0) / (y1 - y0)));
  }
  const HighRhoPoint* b = pts.back();
  std::string best = absl::StrFormat("best %s in %s", Pct(b->max), Seconds(b->wall));
  if (pts.size() >= 3) {
    std::vector<std::pair<double, double>> tail;
    for (size_t k = pts.size() - 3; k < pts.size(); ++k)
      tail.push_back({pts[k]->wall, pts[k]->max});
    const double slope = LogSlope(tail);
    // Only from near the target: far from it (e.g. errors of a bias, not of noise) the trend
    // says nothing.
    if (slope < -0.2 && b->max < 10 * target) {
      return absl::StrFormat("~%s extrap. (%s)",
                             Seconds(b->wall * std::pow(target / b->max, 1 / slope)), best);
    }
  }
  return "not reached (" + best + ")";
}

// The rows of a high_rho CSV by (scene, rho) and series ("method" or "method w=OVERSHOOT").
struct HighRhoData {
  std::vector<std::pair<std::string, std::string>> cases;  // In order of appearance.
  std::map<std::pair<std::string, std::string>, std::map<std::string, std::vector<HighRhoPoint>>>
      series;
  std::map<std::pair<std::string, std::string>, std::string> elements;
};

HighRhoData LoadHighRho(const Table& t) {
  HighRhoData d;
  for (const auto& r : t.rows) {
    auto col = [&](const char* name) {
      const int c = t.Column(name);
      return c >= 0 && c < static_cast<int>(r.size()) ? r[c] : std::string();
    };
    const std::pair<std::string, std::string> key = {col("scene"), col("rho")};
    if (!d.series.count(key)) d.cases.push_back(key);
    d.elements[key] = col("elements");
    std::string series = col("method");
    if (Num(col("overshoot")) != 1) absl::StrAppend(&series, " w=", col("overshoot"));
    HighRhoPoint p;
    p.budget = Num(col("budget"));
    p.wall = Num(col("wall_s"));
    p.rays = Num(col("rays"));
    p.predicted = Num(col("rays_predicted"));
    p.rms = Num(col("rms_lum"));
    p.max = Num(col("max_lum"));
    p.exitant = Num(col("exitant_error"));
    p.load = Num(col("load"));
    p.stop = col("stop");
    p.converged = p.stop == "converged";
    d.series[key][series].push_back(p);
  }
  return d;
}

// The table of times to a 1 % largest element error: a row per (scene, rho), a column per series
// present in the data.
void AppendHighRhoTable(HighRhoData& d, std::string* md) {
  const std::vector<std::pair<std::string, std::string>> all_columns = {
      {"progressive", "progressive"},
      {"progressive w=1.5", "progressive, overshoot 1.5"},
      {"progressive w=2", "progressive, overshoot 2"},
      {"reflection", "reflection"},
      {"gauss-seidel", "gauss-seidel (MC rows)"},
      {"jacobi", "jacobi (MC rows)"},
      {"hierarchical", "hierarchical"}};
  const std::map<std::string, std::string> scene_names = {
      {"furnace", "furnace (closed form)"},
      {"cornell_closed", "closed Cornell box, no blocks"},
      {"cornell", "Cornell box as published"}};
  std::vector<std::pair<std::string, std::string>> columns;
  for (const auto& c : all_columns) {
    for (const auto& key : d.cases) {
      if (d.series[key].count(c.first)) {
        columns.push_back(c);
        break;
      }
    }
  }
  absl::StrAppend(md, "| scene | rho | N |");
  for (const auto& c : columns) absl::StrAppend(md, " ", c.second, " |");
  absl::StrAppend(md, "\n| --- | --- | --- |");
  for (size_t i = 0; i < columns.size(); ++i) absl::StrAppend(md, " --- |");
  absl::StrAppend(md, "\n");
  for (const auto& key : d.cases) {
    const auto it = scene_names.find(key.first);
    absl::StrAppend(md, "| ", it == scene_names.end() ? key.first : it->second, " | ",
                    key.second == "scene" ? "its own" : key.second, " | ", d.elements[key], " |");
    for (const auto& c : columns) {
      const auto s = d.series[key].find(c.first);
      absl::StrAppend(md, " ",
                      s == d.series[key].end() ? std::string("-") : HighRhoCell(s->second, 0.01),
                      " |");
    }
    absl::StrAppend(md, "\n");
  }
}

void AppendHighRhoSection(const ReportOptions& o, std::string* md) {
  absl::StatusOr<Table> t = ReadTable(o.results_dir + "/high_rho.csv");
  if (!t.ok() || t->rows.empty()) return;
  HighRhoData d = LoadHighRho(*t);
  const auto& cases = d.cases;
  auto& data = d.series;
  absl::StrAppend(md, "## High reflectance: which method converges fastest\n\n");
  const auto run = ReadKeyValues(o.results_dir + "/high_rho_run.txt");
  absl::StrAppend(md, "Measured by `bench/run --only high_rho",
                  run.count("mode") && run.at("mode") == "full" ? " --full" : "",
                  "` (`radiosity_bench high_rho`");
  if (run.count("date")) {
    absl::StrAppend(md, ", ", run.at("mode"), " mode) on ", run.at("date"), ", commit ",
                    run.count("commit") ? run.at("commit") : "?", "; the suite took ",
                    run.count("seconds") ? run.at("seconds") : "?", " s, 1-minute load average ",
                    run.count("load_start") ? run.at("load_start") : "?", " at its start and ",
                    run.count("load_end") ? run.at("load_end") : "?",
                    " at its end (every row records it too)");
  } else {
    absl::StrAppend(md, ")");
  }
  absl::StrAppend(
      md,
      ". Scenes: the furnace (`scenes/furnace.json`, a closed unit box with E = 1, every "
      "reflectance set to rho; reference the closed form B = E / (1 - rho)); the Cornell box "
      "without its blocks, closed by a front wall, every reflectance set to rho (a bright room "
      "lit by its small ceiling light; reference `bench/reference/high_rho_cornell_closed_rho*"
      ".ref.gz`, below); and the Cornell box as published at its own reflectances (reference "
      "`cornell_1k`). Each cell is the wall time (2 threads, meshing excluded) to reach a "
      "**largest element error of 1 %** (luminance, every element side), interpolated between "
      "the converged solves of a ladder of budgets, or extrapolated along the last three "
      "(marked): progressive and reflection at H = 3e3, 1e4, 3e4 (quick) ... 3e5 (full) "
      "expected ray landings per element (K = H (1 - rho) rays per element), Gauss-Seidel and "
      "Jacobi at 100 ... 1e5 rays a row, hierarchical at tolerance 1e-2 ... 1e-4; tolerance "
      "1e-3 (the CLI's default) for the others, one seed. A ladder ends once a solve reaches "
      "the target or takes longer than a few seconds; a solve is stopped after 15 s (quick) "
      "or 60 s (full).\n\n");
  AppendHighRhoTable(d, md);
  if (absl::StatusOr<Table> full = ReadTable(o.results_dir + "/high_rho_full.csv");
      full.ok() && !full->rows.empty()) {
    HighRhoData f = LoadHighRho(*full);
    const auto frun = ReadKeyValues(o.results_dir + "/high_rho_full_run.txt");
    auto v = [&](const char* k) { return frun.count(k) ? frun.at(k) : std::string("?"); };
    absl::StrAppend(
        md,
        "\nMeasured down to the target (full ladders, the fastest series only; "
        "`bench/results/high_rho_full.csv`, made by `radiosity_bench high_rho --mode full "
        "--scenes furnace,cornell_closed --methods progressive,gauss-seidel,hierarchical "
        "--stop-after 30 --max-seconds 60 --csv bench/results/high_rho_full.csv` on ",
        v("date"), ", ", v("seconds"), " s, load average ", v("load_start"), " to ", v("load_end"),
        "; the published Cornell box's row appended by the same command with `--scenes cornell "
        "--methods progressive,hierarchical`",
        frun.count("cornell_date") ? absl::StrCat(" on ", v("cornell_date")) : std::string(),
        "):\n\n");
    AppendHighRhoTable(f, md);
  }
  // Rays against the equal-power prediction, and the energy check.
  absl::StrAppend(
      md,
      "\nRays spent by the progressive solver against K N / (1 - rho) (rays of equal "
      "power; Shirley 6.2), and the total exitant power against Phi / (1 - rho) (a "
      "closed room of uniform rho), at the largest converged budget:\n\n"
      "| scene | rho | H | rays | K N / (1 - rho) | ratio | exitant power error | "
      "max error | RMS error |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const auto& key : cases) {
    const auto s = data[key].find("progressive");
    if (s == data[key].end()) continue;
    const HighRhoPoint* last = nullptr;
    for (const HighRhoPoint& p : s->second) {
      if (p.converged) last = &p;
    }
    if (last == nullptr) continue;
    absl::StrAppend(md, "| ", key.first, " | ", key.second, " | ", Fmt(last->budget, "%.3g"), " | ",
                    Fmt(last->rays, "%.3g"), " | ", Fmt(last->predicted, "%.3g"), " | ",
                    Fmt(last->rays / last->predicted, "%.3f"), " | ",
                    std::isfinite(last->exitant) ? absl::StrFormat("%+.2g", last->exitant) : "-",
                    " | ", Pct(last->max), " | ", Pct(last->rms), " |\n");
  }
  // The closed room's references.
  std::string refs;
  for (const auto& key : cases) {
    if (key.first != "cornell_closed") continue;
    const std::string path =
        o.bench_dir + "/reference/high_rho_cornell_closed_rho" + key.second + ".ref.gz";
    absl::StatusOr<Reference> ref = ReadReference(path);
    if (!ref.ok()) continue;
    absl::StrAppend(&refs, "| ", key.second, " | ", ref->meta["elements"], " | ",
                    ref->meta["method"], " | ", ref->meta["check gauss-seidel"], " | ",
                    ref->meta["check progressive"], " | ", ref->meta["check conservation"], " |\n");
  }
  if (!refs.empty()) {
    absl::StrAppend(
        md,
        "\nReferences of the closed room (`radiosity_bench high_rho --scenes "
        "cornell_closed --methods none --make-references`, about 40 s each):\n\n"
        "| rho | N | made by | check: Gauss-Seidel, 1e5 rays a row | check: "
        "progressive, H = 1e5 | conservation |\n| --- | --- | --- | --- | --- | --- |\n",
        refs);
  }
  absl::StrAppend(md, "\n");
  const std::string discussion = ReadText(o.bench_dir + "/high_rho.md");
  if (!discussion.empty()) absl::StrAppend(md, discussion, "\n");
}

// ---- Accuracy per second (issue 13; bench/run --only accuracy): accuracy.csv, one row per seed,
// and accuracy_sensors.csv. Means over seeds; the estimated RMS is the solver's own (summary.json
// std_error_rms_relative), to compare with the measured one.
void AppendAccuracySection(const ReportOptions& o, std::string* md) {
  absl::StatusOr<Table> t = ReadTable(o.results_dir + "/accuracy.csv");
  if (!t.ok() || t->rows.empty()) return;
  struct Row {
    std::string suite, estimator, budget;
    double elements = 0, wall = 0, rms = 0, max = 0, est = 0;
    int count = 0;
  };
  std::vector<Row> rows;
  for (const auto& r : t->rows) {
    auto col = [&](const char* name) {
      const int c = t->Column(name);
      return c >= 0 && c < static_cast<int>(r.size()) ? r[c] : std::string();
    };
    const std::string suite = col("suite"), budget = col("budget");
    const std::string estimator = col("method") + " / " + col("estimator");
    Row* row = nullptr;
    for (Row& x : rows) {
      if (x.suite == suite && x.estimator == estimator && x.budget == budget) row = &x;
    }
    if (row == nullptr) {
      rows.push_back({suite, estimator, budget});
      row = &rows.back();
    }
    row->elements = Num(col("elements"));
    row->wall += Num(col("wall_s"));
    row->rms += Num(col("rms_lum"));
    row->max += Num(col("max_lum"));
    row->est += Num(col("est_rms_lum"));
    ++row->count;
  }
  const auto run = ReadKeyValues(o.results_dir + "/accuracy_run.txt");
  absl::StrAppend(
      md, "## Accuracy per second\n\n", "Measured by `bench/run --only accuracy`",
      run.count("date") ? " on " + run.at("date") : std::string(),
      run.count("commit") ? " (commit " + run.at("commit") + ")" : std::string(),
      ", 2 cores, means over the seeds of each row. `progressive / montecarlo` is the default "
      "progressive solve (direct light computed, Sobol' rays, indirect light per "
      "patch); `montecarlo-random-shot-element` the chapter's shooting "
      "(`--sampling random --direct shot --indirect element`); other labels change one "
      "of the three. Budget: rays per element. Estimated RMS: the solver's own "
      "(`std_error_rms_relative`). bench/REPORT.md discusses them.\n\n",
      "| suite | elements | solve | budget | seeds | wall | RMS error | worst element "
      "| estimated RMS |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Row& r : rows) {
    const double n = r.count;
    absl::StrAppend(md, "| ", r.suite, " | ", Fmt(r.elements, "%.0f"), " | ", r.estimator, " | ",
                    r.budget, " | ", r.count, " | ", Seconds(r.wall / n), " | ", Pct(r.rms / n),
                    " | ", Pct(r.max / n), " | ", r.est > 0 ? Pct(r.est / n) : std::string("-"),
                    " |\n");
  }
  absl::StrAppend(md, "\n");
  absl::StatusOr<Table> sensors = ReadTable(o.results_dir + "/accuracy_sensors.csv");
  if (!sensors.ok() || sensors->rows.empty()) return;
  absl::StrAppend(
      md,
      "Sensor points (`radiosity_bench sensors`; rms, max and the estimated RMS "
      "relative to the reference irradiance; one row per seed):\n\n"
      "| label | scene | rays/element | gather samples | threads | seed | wall | RMS "
      "| worst | estimated RMS |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- "
      "| --- |\n");
  for (const auto& r : sensors->rows) {
    auto col = [&](const char* name) {
      const int c = sensors->Column(name);
      return c >= 0 && c < static_cast<int>(r.size()) ? r[c] : std::string();
    };
    absl::StrAppend(md, "| ", col("label"), " | `", col("scene"), "` | ", col("rays_per_element"),
                    " | ", col("sensor_samples"), " | ", col("threads"), " | ", col("seed"), " | ",
                    Seconds(Num(col("wall_s"))), " | ", Pct(Num(col("rms"))), " | ",
                    Pct(Num(col("max"))), " | ", Pct(Num(col("est_rms"))), " |\n");
  }
  absl::StrAppend(md, "\n");
}

absl::Status WriteReport(const ReportOptions& o) {
  fs::create_directories(o.figures_dir);
  const auto machine = ReadKeyValues(o.results_dir + "/machine.txt");
  auto m = [&](const char* k) {
    auto it = machine.find(k);
    return it == machine.end() ? std::string("?") : it->second;
  };

  std::vector<Suite> suites;
  for (const SuiteInfo& info : kSuites) {
    const std::string path = o.results_dir + "/" + info.name + ".csv";
    if (!fs::exists(path)) continue;
    absl::StatusOr<Suite> s = LoadSuite(path, info.name);
    if (!s.ok()) return s.status();
    if (absl::Status st = PlotSuite(o, *s, info.title); !st.ok()) return st;
    suites.push_back(*std::move(s));
  }
  auto find_suite = [&](const std::string& name) -> const Suite* {
    for (const Suite& s : suites) {
      if (s.name == name) return &s;
    }
    return nullptr;
  };

  std::string md;
  absl::StrAppend(&md, "# Speed against error\n\n");
  absl::StrAppend(
      &md, "Generated by `bench/run", o.mode == "full" ? " --full" : "", "` (", o.mode,
      " mode) on ", m("date"), ", commit ", m("commit"), "; the run took ", m("seconds"),
      " s. Everything below is regenerated by that command from `bench/results/*.csv` except the "
      "last section, *Discussion*, written by hand (`bench/discussion.md`) about the run named "
      "there. Nothing here is a pass/fail test: targets are reported as measured.\n\n");

  // ---- Machine.
  absl::StrAppend(&md, "## Machine\n\n| | |\n| --- | --- |\n");
  for (const char* k : {"cpu", "nproc", "memory", "kernel", "compiler", "build"}) {
    absl::StrAppend(&md, "| ", k, " | ", m(k), " |\n");
  }
  absl::StrAppend(&md, "| load average (1 min) | ", m("load_start"), " at the start, ",
                  m("load_end"),
                  " at the end (each CSV row records it too; above ~2 on this 2-core machine "
                  "another process was competing and times are inflated) |\n\n");

  // ---- Headline: the targets.
  const Suite* c10k = find_suite("cornell_10k");
  const Suite* c100k = find_suite("cornell_100k");
  const Suite* c1m = find_suite("cornell_1m");
  struct Best {
    std::string series;
    Reach reach;
  };
  auto best = [&](const Suite* s, double target) {
    Best b;
    if (s == nullptr) return b;
    for (const Series& ser : s->series) {
      Reach r = TimeToReach(ser, target);
      if (r.reached && (!b.reach.reached || r.seconds < b.reach.seconds)) b = {ser.key, r};
      if (!b.reach.reached && !r.reached && std::isfinite(r.extrapolated) &&
          (!std::isfinite(b.reach.extrapolated) || r.extrapolated < b.reach.extrapolated)) {
        b = {ser.key, r};
      }
    }
    return b;
  };

  // Scaling data (used by the targets' 10^6 estimate, and its own section).
  std::vector<std::pair<double, double>> time_vs_n, mem_vs_n, rays_vs_n;
  struct ScaleRow {
    double n, wall, cpu, rays, peak, start, per_element;
  };
  std::vector<ScaleRow> scale_rows;
  if (absl::StatusOr<Table> t = ReadTable(o.results_dir + "/scaling.csv"); t.ok()) {
    for (const auto& row : t->rows) {
      ScaleRow r{Num(row[t->Column("elements")]),
                 Num(row[t->Column("wall_s")]),
                 Num(row[t->Column("cpu_s")]),
                 Num(row[t->Column("rays")]),
                 Num(row[t->Column("peak_rss_mib")]),
                 Num(row[t->Column("start_rss_mib")]),
                 Num(row[t->Column("bytes_per_element")])};
      scale_rows.push_back(r);
      time_vs_n.push_back({r.n, r.wall});
      rays_vs_n.push_back({r.n, r.rays});
    }
  }
  std::sort(scale_rows.begin(), scale_rows.end(),
            [](const ScaleRow& a, const ScaleRow& b) { return a.n < b.n; });
  const double time_exponent = LogSlope(time_vs_n);
  // Marginal memory per element: least squares of (peak - start) on N.
  double marginal_bytes = NAN;
  {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int n = 0;
    for (const ScaleRow& r : scale_rows) {
      const double y = (r.peak - r.start) * 1048576.0;
      sx += r.n;
      sy += y;
      sxx += r.n * r.n;
      sxy += r.n * y;
      ++n;
    }
    if (n >= 2 && n * sxx - sx * sx > 0) marginal_bytes = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  }

  absl::StrAppend(&md, "## Targets (as measured)\n\n");
  absl::StrAppend(&md,
                  "| target | fastest method | measured | against the target |\n| --- | --- | --- "
                  "| --- |\n");
  auto target_row = [&](const std::string& what, const Suite* s, double error, double limit) {
    Best b = best(s, error);
    std::string measured = s == nullptr ? "not run" : ReachText(b.reach);
    std::string verdict = "-";
    double t = b.reach.reached ? b.reach.seconds : b.reach.extrapolated;
    if (std::isfinite(t)) {
      verdict = t <= limit ? absl::StrFormat("met (%.2g x the limit)", t / limit)
                           : absl::StrFormat("missed: %.1f x over", t / limit);
      if (!b.reach.reached) verdict += " (extrapolated)";
    }
    absl::StrAppend(&md, "| ", what, " | ", b.series.empty() ? "-" : "`" + b.series + "`", " | ",
                    measured, " | ", verdict, " |\n");
  };
  target_row("Cornell box ~10 k elements to 1 % RMS in < 2 s", c10k, 0.01, 2);
  target_row("Cornell box ~100 k elements to 1 % RMS in < 20 s", c100k, 0.01, 20);
  if (c1m != nullptr) {
    target_row("Cornell box ~10^6 elements to 2 % RMS in < 2 min", c1m, 0.02, 120);
  } else if (c100k != nullptr) {
    // Quick mode: the error at a fixed number of rays per element does not depend on N (the
    // claim, measured below), and the time grows like N^a (the scaling fit): scale 100 k.
    const Series* p = c100k->Find("progressive/montecarlo");
    Reach r = p ? TimeToReach(*p, 0.02) : Reach{};
    double t100k = r.reached ? r.seconds : r.extrapolated;
    double scale = std::isfinite(time_exponent) ? std::pow(10.0, time_exponent) : 10.0;
    double t = t100k * scale;
    absl::StrAppend(
        &md, "| Cornell box ~10^6 elements to 2 % RMS in < 2 min | `progressive/montecarlo` | ~",
        Seconds(t), " (estimated: 100 k elements to 2 % = ", Seconds(t100k), ", x 10^",
        Fmt(time_exponent, "%.2f"), " from the scaling fit; `--full` measures it) | ",
        std::isfinite(t) ? (t <= 120 ? "met (estimate)"
                                     : absl::StrFormat("missed: %.1f x over (estimate)", t / 120))
                         : "-",
        " |\n");
  }
  absl::StrAppend(
      &md, "| progressive solver memory linear in N, < 1 KiB per element | - | ",
      std::isfinite(marginal_bytes)
          ? absl::StrFormat("%.0f bytes per element (marginal, least squares over N = %s to %s)",
                            marginal_bytes, Fmt(scale_rows.front().n, "%.0f"),
                            Fmt(scale_rows.back().n, "%.0f"))
          : "-",
      " | ", std::isfinite(marginal_bytes) ? (marginal_bytes < 1024 ? "met" : "missed") : "-",
      " |\n");
  // Throughput target.
  double tp_ratio = NAN;
  std::string tp_rows;
  if (absl::StatusOr<Table> t = ReadTable(o.results_dir + "/throughput.csv"); t.ok()) {
    for (const auto& row : t->rows) {
      const double ratio = Num(row[t->Column("ratio_solver_raw")]);
      if (row[t->Column("scene")] == "cornell_box" && row[t->Column("threads")] == "2")
        tp_ratio = ratio;
      absl::StrAppend(&tp_rows, "| ", row[t->Column("scene")], " | ", row[t->Column("elements")],
                      " | ", row[t->Column("threads")], " | ",
                      Fmt(Num(row[t->Column("solver_rays_per_s")]) / 1e6, "%.2f"), " M | ",
                      Fmt(Num(row[t->Column("raw_rays_per_s")]) / 1e6, "%.2f"), " M | ",
                      Fmt(Num(row[t->Column("raw_gen_rays_per_s")]) / 1e6, "%.2f"), " M | ",
                      Fmt(ratio, "%.2f"), " | ",
                      Fmt(Num(row[t->Column("ratio_solver_raw_gen")]), "%.2f"), " | ",
                      row[t->Column("load")], " |\n");
    }
  }
  absl::StrAppend(
      &md,
      "| solver ray throughput >= 80 % of raw Embree (Cornell 10 k, 2 threads) | "
      "`progressive` | ",
      std::isfinite(tp_ratio) ? absl::StrFormat("%.0f %% of raw", 100 * tp_ratio) : "-", " | ",
      std::isfinite(tp_ratio)
          ? (tp_ratio >= 0.8 ? "met"
                             : absl::StrFormat("missed by %.0f points", 100 * (0.8 - tp_ratio)))
          : "-",
      " |\n\n");
  absl::StrAppend(&md,
                  "Times are wall-clock seconds of the solve alone (meshing and the Embree build "
                  "excluded; they are in the CSVs as `mesh_s`), with the errors corrected for the "
                  "reference's own noise (see *Metrics*).\n\n");
  if (c10k != nullptr) {
    absl::StrAppend(&md, "![error against time, Cornell box 10 k](figures/cornell_10k.png)\n\n");
  }

  // ---- Time-to-error table.
  absl::StrAppend(&md, "## Time to reach 10 %, 3 % and 1 % RMS error\n\n");
  absl::StrAppend(
      &md,
      "Wall time for the area-weighted RMS relative error of element luminance to fall to each "
      "level, interpolated on the log-log error-time curve between the two budgets around it "
      "(`<=` : already below at the cheapest budget tried). *Order* is the slope of log error "
      "against log time (Monte Carlo: -1/2; a flat slope means the estimator's bias, not its "
      "noise, dominates). *Best* is the smallest error reached, with its time.\n\n");
  absl::StrAppend(&md, "| scene | N | method / estimator | 10 % | 3 % | 1 % | order | best |\n");
  absl::StrAppend(&md, "| --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Suite& s : suites) {
    for (const Series& ser : s.series) {
      const Point* bestp = nullptr;
      for (const Point& p : ser.points) {
        if (std::isfinite(p.rms) && (bestp == nullptr || p.Corrected() < bestp->Corrected()))
          bestp = &p;
      }
      absl::StrAppend(
          &md, "| ", s.name, " | ", s.elements, " | ", ser.key, " | ",
          ReachText(TimeToReach(ser, 0.10)), " | ", ReachText(TimeToReach(ser, 0.03)), " | ",
          ReachText(TimeToReach(ser, 0.01)), " | ", Fmt(ConvergenceSlope(ser), "%.2f"), " | ",
          bestp ? absl::StrCat(Pct(bestp->Corrected()), " in ", Seconds(bestp->wall)) : "-",
          " |\n");
    }
  }
  absl::StrAppend(&md, "\n");

  // ---- Figures per suite.
  absl::StrAppend(&md, "## Error against time\n\n");
  absl::StrAppend(
      &md,
      "One line per method / estimator; points are the budgets of the ladder (rays per element "
      "for Monte Carlo, hemicube resolution, analytic receiver points x shadow rays; labelled on "
      "the main lines). Dotted: 10 %, 3 %, 1 %; dash-dotted: the reference's own noise, below "
      "which a measured error means little.\n\n");
  for (const Suite& s : suites) {
    for (const SuiteInfo& info : kSuites) {
      if (s.name != info.name) continue;
      absl::StrAppend(&md, "### ", info.title, "\n\n![", s.name, "](figures/", s.name, ".png)\n\n");
    }
    // Per-series summary: errors at the largest budget, the worst elements, energy.
    absl::StrAppend(&md,
                    "| method / estimator | largest budget | time | rays | RMS | p99 | max | power "
                    "error | balance | peak RSS |\n");
    absl::StrAppend(&md, "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    for (const Series& ser : s.series) {
      if (ser.points.empty()) continue;
      const Point& p = ser.points.back();
      absl::StrAppend(&md, "| ", ser.key, " | ", p.budget, " | ", Seconds(p.wall), " | ",
                      Fmt(p.rays, "%.3g"), " | ", Pct(p.rms), " | ", Pct(p.p99), " | ", Pct(p.max),
                      " | ", Fmt(p.power, "%.2g"), " | ", Fmt(p.balance, "%.1g"), " | ",
                      Fmt(p.peak, "%.0f"), " MiB |\n");
    }
    absl::StrAppend(&md, "\n");
  }

  // ---- The chapter's claim.
  absl::StrAppend(
      &md, "## The chapter's claim: constant error at a fixed number of rays per element\n\n");
  absl::StrAppend(
      &md,
      "Shirley (thesis, 6.2 and Fig. 6.9): with the number of rays proportional to the number of "
      "elements N, the error of the Monte Carlo solution stays roughly constant, so a solve costs "
      "O(N) rays. Below: the progressive solver's error at each fixed rays-per-element budget, "
      "for N from 1 k to 100 k (three seeds each, against the stored references; RMS corrected "
      "for the reference's noise) and 10^6 (full mode only: from two seeds, see the check "
      "below), and the least-squares slope of log error against log N (0: the claim holds; "
      "-1/2 or +1/2 would mean error falling or growing like the square root of N). The RMS "
      "of relative errors is dominated by a few dark elements (the floor at the foot of the "
      "blocks, which get few rays), so it varies from seed to seed; the 99th percentile is "
      "steadier.\n\n");
  // budget -> N -> per-seed (corrected RMS, p99), from claim.csv (several seeds against the
  // stored references) and cornell_1m.csv (two-seed estimates, full mode).
  std::map<double, std::map<double, std::vector<ClaimPoint>>> claim;
  std::map<double, std::map<double, std::vector<double>>> claim_p99;
  for (const char* file : {"claim.csv", "cornell_1m.csv"}) {
    absl::StatusOr<Table> t = ReadTable(o.results_dir + "/" + file);
    if (!t.ok()) continue;
    for (const auto& row : t->rows) {
      if (row[t->Column("method")] != "progressive") continue;
      Point p;
      p.rms = Num(row[t->Column("rms_lum")]);
      p.noise = Num(row[t->Column("ref_noise")]);
      if (!std::isfinite(p.noise)) p.noise = 0;
      const double budget = Num(row[t->Column("budget")]);
      const double n = Num(row[t->Column("elements")]);
      if (!std::isfinite(p.rms)) continue;
      claim[budget][n].push_back({n, p.Corrected(), file});
      claim_p99[budget][n].push_back(Num(row[t->Column("p99_lum")]));
    }
  }
  {
    const std::string dat = o.results_dir + "/plot_claim.dat";
    std::ofstream d(dat);
    std::vector<std::string> plots;
    int index = 0;
    absl::StrAppend(&md,
                    "| rays per element | RMS error by N (mean over seeds, [min, max]) | slope "
                    "of log RMS vs log N | p99 by N | slope of log p99 vs log N |\n| --- | --- | "
                    "--- | --- | --- |\n");
    for (const auto& [budget, by_n] : claim) {
      if (by_n.size() < 2) continue;
      std::vector<std::pair<double, double>> xy, xy99;
      std::vector<std::string> cells, cells99;
      d << "# " << budget << "\n";
      for (const auto& [n, pts] : by_n) {
        double mean = 0, lo = 1e300, hi = 0;
        for (const ClaimPoint& c : pts) {
          mean += c.error / pts.size();
          lo = std::min(lo, c.error);
          hi = std::max(hi, c.error);
        }
        double p99 = 0;
        for (double v : claim_p99[budget][n]) p99 += v / claim_p99[budget][n].size();
        xy.push_back({n, mean});
        xy99.push_back({n, p99});
        cells.push_back(pts.size() > 1 ? absl::StrCat(Fmt(n, "%.0f"), ": ", Pct(mean), " [",
                                                      Pct(lo), ", ", Pct(hi), "]")
                                       : absl::StrCat(Fmt(n, "%.0f"), ": ", Pct(mean)));
        cells99.push_back(absl::StrCat(Fmt(n, "%.0f"), ": ", Pct(p99)));
        d << absl::StrFormat("%.6g %.6g %.6g %.6g %.6g\n", n, mean, lo, hi, p99);
      }
      d << "\n\n";
      const double slope = LogSlope(xy), slope99 = LogSlope(xy99);
      absl::StrAppend(&md, "| ", Fmt(budget, "%g"), " | ", absl::StrJoin(cells, "<br>"), " | ",
                      Fmt(slope, "%+.3f"), " | ", absl::StrJoin(cells99, "<br>"), " | ",
                      Fmt(slope99, "%+.3f"), " |\n");
      plots.push_back(absl::StrFormat(
          "'%s' index %d using 1:2:3:4 with yerrorlines lw 2 pt 7 lc %d title '%g rays/element, "
          "RMS (slope %+.2f)', '%s' index %d using 1:5 with linespoints dt 2 pt 6 lc %d title "
          "'p99 (slope %+.2f)'",
          Escape(dat), index, index + 1, budget, slope, Escape(dat), index, index + 1, slope99));
      ++index;
    }
    d.close();
    absl::StrAppend(&md, "\n");
    if (!plots.empty()) {
      const std::string gp = o.results_dir + "/plot_claim.gp";
      std::ofstream g(gp);
      g << "set terminal pngcairo size 900,560 enhanced font 'Sans,10'\n";
      g << "set output '" << Escape(o.figures_dir + "/claim.png") << "'\n";
      g << "set title 'Progressive solver, Cornell box: error at a fixed number of rays per "
           "element'\n";
      g << "set logscale xy\nset grid\nset format y '%g'\nset format x '%g'\n";
      g << "set xlabel 'elements N'\nset ylabel 'relative error (luminance)'\n";
      g << "set key outside right top\nset xrange [500:*]\n";
      g << "plot " << absl::StrJoin(plots, ", \\\n     ") << "\n";
      g.close();
      std::system(absl::StrCat(o.gnuplot, " '", gp, "' 2>&1").c_str());
      absl::StrAppend(&md, "![claim](figures/claim.png)\n\n");
    }
  }
  // The two-seed estimate against the reference, at 100 k.
  if (absl::StatusOr<Table> t = ReadTable(o.results_dir + "/pair_check.csv"); t.ok() && c100k) {
    const Series* p = c100k->Find("progressive/montecarlo");
    absl::StrAppend(&md,
                    "Check of the two-seed error estimate used at 10^6 elements (Cornell box, 100 "
                    "k elements): ");
    std::vector<std::string> parts;
    for (const auto& row : t->rows) {
      const std::string budget = row[t->Column("budget")];
      double against = NAN;
      if (p) {
        for (const Point& q : p->points) {
          if (q.budget == budget) against = q.Corrected();
        }
      }
      parts.push_back(absl::StrCat(budget, " rays/element: two seeds ",
                                   Pct(Num(row[t->Column("rms_lum")])), ", reference ",
                                   Pct(against)));
    }
    absl::StrAppend(&md, absl::StrJoin(parts, "; "), ".\n\n");
  }

  // ---- Scaling.
  absl::StrAppend(&md, "## Scaling with N (progressive, 100 rays per element)\n\n");
  if (!scale_rows.empty()) {
    absl::StrAppend(&md,
                    "One process per N (so that the peak resident set is the process's own); "
                    "memory is the peak RSS minus the RSS at start-up (shared libraries).\n\n");
    absl::StrAppend(
        &md,
        "| N | wall | CPU | rays | rays/s | peak RSS | above start-up | bytes per element |\n");
    absl::StrAppend(&md, "| --- | --- | --- | --- | --- | --- | --- | --- |\n");
    const std::string dat = o.results_dir + "/plot_scaling.dat";
    std::ofstream d(dat);
    for (const ScaleRow& r : scale_rows) {
      absl::StrAppend(&md, "| ", Fmt(r.n, "%.0f"), " | ", Seconds(r.wall), " | ", Seconds(r.cpu),
                      " | ", Fmt(r.rays, "%.3g"), " | ", Fmt(r.rays / r.wall / 1e6, "%.2f"),
                      " M | ", Fmt(r.peak, "%.0f"), " MiB | ", Fmt(r.peak - r.start, "%.1f"),
                      " MiB | ", Fmt(r.per_element, "%.0f"), " |\n");
      d << absl::StrFormat("%.6g %.6g %.6g %.6g %.6g\n", r.n, r.wall, r.per_element,
                           r.rays / r.wall, r.peak - r.start);
    }
    d.close();
    absl::StrAppend(&md, "\nTime grows like N^", Fmt(time_exponent, "%.2f"),
                    " (least squares; rays like N^", Fmt(LogSlope(rays_vs_n), "%.2f"),
                    "). Memory: ", Fmt(marginal_bytes, "%.0f"),
                    " bytes per additional element (least-squares slope of the memory above "
                    "start-up against N); the per-element column includes the fixed cost "
                    "(thread pool, ray buffers), which dominates at small N.\n\n");
    const std::string gp = o.results_dir + "/plot_scaling.gp";
    std::ofstream g(gp);
    g << "set terminal pngcairo size 1000,420 enhanced font 'Sans,10'\n";
    g << "set output '" << Escape(o.figures_dir + "/scaling.png") << "'\n";
    g << "set multiplot layout 1,2\nset logscale xy\nset grid\nset format x '%g'\nset format y "
         "'%g'\n";
    g << "set xlabel 'elements N'\nset ylabel 'wall time (s)'\n";
    g << "set title 'Progressive, 100 rays/element: time'\n";
    g << "plot '" << Escape(dat) << "' using 1:2 with linespoints lw 2 pt 7 title 'measured', "
      << "'" << Escape(dat) << "' using 1:($2*0+"
      << (scale_rows.empty() ? 1 : scale_rows.back().wall) << "*$1/"
      << (scale_rows.empty() ? 1 : scale_rows.back().n) << ") with lines dt 2 title 'linear'\n";
    g << "set ylabel 'peak RSS above start-up (MiB)'\n";
    g << "set title 'memory'\nset key left top\n";
    g << "plot '" << Escape(dat) << "' using 1:5 with linespoints lw 2 pt 7 title 'measured', "
      << "x * 1024 / 1048576 with lines dt 2 title '1 KiB per element'\n";
    g << "unset multiplot\n";
    g.close();
    std::system(absl::StrCat(o.gnuplot, " '", gp, "' 2>&1").c_str());
    absl::StrAppend(&md, "![scaling](figures/scaling.png)\n\n");
  }
  if (absl::StatusOr<Table> t = ReadTable(o.results_dir + "/threads.csv"); t.ok()) {
    absl::StrAppend(&md,
                    "Speed-up from 1 to 2 threads (Cornell box, ~10 k elements; same answer "
                    "whatever the thread count):\n\n");
    absl::StrAppend(&md,
                    "| method / estimator | budget | 1 thread | 2 threads | speed-up | CPU time at "
                    "2 threads | load |\n| --- | --- | --- | --- | --- | --- | --- |\n");
    std::map<std::string, std::map<std::string, std::vector<std::string>>>
        by;  // key -> threads -> row
    std::vector<std::string> keys;
    for (const auto& row : t->rows) {
      const std::string key = row[t->Column("method")] + "/" + row[t->Column("estimator")] + "|" +
                              row[t->Column("budget")];
      if (!by.count(key)) keys.push_back(key);
      by[key][row[t->Column("threads")]] = row;
    }
    for (const std::string& key : keys) {
      auto& r = by[key];
      if (!r.count("1") || !r.count("2")) continue;
      const double w1 = Num(r["1"][t->Column("wall_s")]), w2 = Num(r["2"][t->Column("wall_s")]);
      const size_t bar = key.find('|');
      absl::StrAppend(&md, "| ", key.substr(0, bar), " | ", key.substr(bar + 1), " | ", Seconds(w1),
                      " | ", Seconds(w2), " | ", Fmt(w1 / w2, "%.2f"), " x | ",
                      Seconds(Num(r["2"][t->Column("cpu_s")])), " | ", r["1"][t->Column("load")],
                      " / ", r["2"][t->Column("load")], " |\n");
    }
    absl::StrAppend(&md, "\n");
  }

  // ---- Throughput.
  absl::StrAppend(&md, "## Ray throughput\n\n");
  if (!tp_rows.empty()) {
    absl::StrAppend(
        &md,
        "Rays per second inside the progressive solver (all rays of a solve to 1e-3 unshot, over "
        "its wall time: ray generation, Embree, element lookup, the serial deposit of power and "
        "the choice of shooters) against raw Embree in the same process on the same scene: "
        "`Visibility::Intersect` (`rtcIntersect1` with the solver's filter that skips the "
        "origin's face) on pre-generated rays of the same kind (cosine-distributed from "
        "area-uniform points, as many as the solver traced), and the same with the ray "
        "generation and element lookup included.\n\n");
    absl::StrAppend(&md,
                    "| scene | N | threads | solver rays/s | raw Embree rays/s | raw + generation "
                    "+ lookup | solver / raw | solver / (raw + gen.) | load |\n");
    absl::StrAppend(&md, "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n", tp_rows,
                    "\n");
  }

  // ---- Profiles.
  for (const auto& [file, what] : std::vector<std::pair<std::string, std::string>>{
           {"profile_progressive.txt", "progressive, Cornell box 10 k elements, 3000 rays/element"},
           {"profile_hemicube.txt",
            "Gauss-Seidel with hemicube rows (resolution 32), Cornell box 10 k"}}) {
    const std::string text = ReadText(o.results_dir + "/" + file);
    if (text.empty()) continue;
    absl::StrAppend(&md, "## Profile: ", what,
                    "\n\n`perf record -g` over the solve (self time, "
                    "symbols above 1.5 %):\n\n```\n",
                    text, "```\n\n");
  }

  // ---- Adaptive and hierarchical against uniform meshes.
  AppendMeshesSection(o, &md);

  // ---- Reflectance near 1.
  AppendHighRhoSection(o, &md);

  // ---- Accuracy per second.
  AppendAccuracySection(o, &md);

  // ---- Answers before convergence and hard cases (hand-written from bench/anytime.py's runs).
  const std::string anytime = ReadText(o.bench_dir + "/anytime.md");
  if (!anytime.empty()) absl::StrAppend(&md, anytime, "\n");

  // ---- Figures the manual (docs/) refers to (hand-written, each with its date and command).
  const std::string manual = ReadText(o.bench_dir + "/manual.md");
  if (!manual.empty()) absl::StrAppend(&md, manual, "\n");

  // ---- References and metrics.
  absl::StrAppend(&md,
                  "## References\n\n| suite | elements | made by | noise of the reference (RMS) | "
                  "cross-checks |\n| --- | --- | --- | --- | --- |\n");
  for (const SuiteInfo& info : kSuites) {
    const std::string path = o.bench_dir + "/reference/" + info.name + ".ref.gz";
    if (!fs::exists(path)) continue;
    absl::StatusOr<Reference> ref = ReadReference(path);
    if (!ref.ok()) continue;
    std::vector<std::string> checks;
    for (const auto& [k, v] : ref->meta) {
      if (k.rfind("check ", 0) == 0) checks.push_back(absl::StrCat("`", k.substr(6), "`: ", v));
    }
    absl::StrAppend(&md, "| ", info.name, " | ", ref->meta["elements"], " | ", ref->meta["method"],
                    " | ", ref->meta["noise_rms"], " | ", absl::StrJoin(checks, "<br>"), " |\n");
  }
  absl::StrAppend(
      &md,
      "\nThe exact commands are in `bench/reference/README.md`; `bench/run --make-references` "
      "regenerates them. Cross-check RMS values include both solutions' noise.\n\n");
  absl::StrAppend(
      &md, "## Metrics\n\n",
      "- **RMS relative error** (`rms_lum`, and `rms_r`, `rms_g`, `rms_b` per channel): "
      "sqrt(sum_i A_i e_i^2 / sum_i A_i) over every element side, with e_i = |B_i - B_i^ref| / "
      "max(B_i^ref, 1e-3 x the area-weighted mean of B^ref) (the floor only matters for "
      "elements the light never reaches, such as the floor under a block).\n",
      "- **p99** and **max**: the area-weighted 99th percentile and the largest e_i (luminance).\n",
      "- **power error**: (sum A_i B_i - sum A_i B_i^ref) / sum A_i B_i^ref (luminance): a bias "
      "in the total light.\n",
      "- **balance**: the solver's own books, (emitted - absorbed - escaped - unshot) / emitted: "
      "rounding for progressive and the matrix methods, Monte Carlo noise for reflection (Russian "
      "roulette conserves energy in expectation only).\n",
      "- **Reference noise**: every reference carries its own Monte Carlo noise n (RMS, from two "
      "seeds). For independent errors E[measured^2] = true^2 + n^2, so the times to reach an "
      "error and the claim use sqrt(measured^2 - n^2) (limited to a correction of 3x); the plots "
      "show the measured values and n as a line.\n",
      "- **Time**: wall time of `CreateSolver` + `RunSolver` (matrix assembly included, meshing "
      "and the Embree build not), CPU time from `getrusage` (all threads), peak memory from "
      "VmHWM, reset before each solve.\n\n");

  // ---- Discussion (hand-written).
  const std::string discussion = ReadText(o.bench_dir + "/discussion.md");
  if (!discussion.empty()) absl::StrAppend(&md, discussion);

  std::ofstream out(o.out);
  out << md;
  out.close();
  if (!out) return absl::InternalError(absl::StrCat(o.out, ": cannot write"));
  return absl::OkStatus();
}

}  // namespace radiosity::bench

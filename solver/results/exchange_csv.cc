#include "solver/results/exchange_csv.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/results/text_writer.h"

namespace radiosity {

absl::Status WriteExchangeCsv(const RadiantExchange& x, const std::string& path) {
  OutputFile file(path, "radiative exchange CSV");
  if (absl::Status st = file.Open(); !st.ok()) return st;
  std::string text =
      "surface,area,emissivity,temperature,emitted_W,absorbed_W,net_W,net_W_per_m2,"
      "to_environment_W\n";
  for (int i = 0; i < x.size(); ++i) {
    absl::StrAppend(
        &text, CsvField(x.surfaces[i]),
        absl::StrFormat(",%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g\n", x.area[i],
                        x.emissivity[i], x.temperature[i], x.emitted[i], x.absorbed[i], x.net[i],
                        x.area[i] > 0 ? x.net[i] / x.area[i] : 0.0, x.to_environment[i]));
  }
  if (absl::Status st = file.Write(text); !st.ok()) return st;
  return file.Close();
}

absl::Status WriteGebhartCsv(const RadiantExchange& x, const std::string& path) {
  OutputFile file(path, "Gebhart factors CSV");
  if (absl::Status st = file.Open(); !st.ok()) return st;
  if (absl::Status st = file.Write("from,to,gebhart,net_W\n"); !st.ok()) return st;
  std::string text;
  for (int i = 0; i < x.size(); ++i) {
    text.clear();
    for (int j = 0; j < x.size(); ++j) {
      if (x.b(i, j) == 0) continue;
      absl::StrAppend(&text, CsvField(x.surfaces[i]), ",", CsvField(x.surfaces[j]),
                      absl::StrFormat(",%.12g,%.12g\n", x.b(i, j), x.NetPair(i, j)));
    }
    if (absl::Status st = file.Write(text); !st.ok()) return st;
  }
  return file.Close();
}

}  // namespace radiosity

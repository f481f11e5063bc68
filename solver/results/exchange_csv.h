// Radiative exchange as files for thermal codes (docs/guide/view-factors.md):
//   exchange.csv  surface,area,emissivity,temperature,emitted_W,absorbed_W,net_W,net_W_per_m2,
//                 to_environment_W     one row per surface, in scene order
//   gebhart.csv   from,to,gebhart,net_W     one row per nonzero Gebhart factor B_ij, row-major;
//                 net_W is the net power from `from` to `to` (E_i B_ij - E_j B_ji)
#ifndef RADIOSITY_SOLVER_RESULTS_EXCHANGE_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_EXCHANGE_CSV_H_

#include <string>

#include "absl/status/status.h"
#include "solver/methods/exchange.h"

namespace radiosity {

absl::Status WriteExchangeCsv(const RadiantExchange& exchange, const std::string& path);
absl::Status WriteGebhartCsv(const RadiantExchange& exchange, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_EXCHANGE_CSV_H_

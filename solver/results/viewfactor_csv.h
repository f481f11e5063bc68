// The view-factor matrix as CSV (`radiosity viewfactor --out`).
#ifndef RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_

#include <string>

#include "absl/status/status.h"
#include "solver/methods/viewfactor.h"

namespace radiosity {

// CSV with the header exactly "from,to,F": one row for every ordered pair with F > 0.
absl::Status WriteViewFactorCsv(const ViewFactorMatrix& matrix, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_

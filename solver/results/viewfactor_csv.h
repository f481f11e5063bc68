// The view-factor matrix as CSV (`radiosity viewfactor --out`).
#ifndef RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_

#include <string>

#include "absl/status/status.h"
#include "solver/methods/viewfactor.h"

namespace radiosity {

// CSV with the header exactly "from,to,F": one row for every ordered pair with F > 0.
absl::Status WriteViewFactorCsv(const ViewFactorMatrix& matrix, const std::string& path);

// The same as a sparse Matrix Market file (NIST's exchange format, which SciPy's mmread, MATLAB
// and Julia read): the banner "%%MatrixMarket matrix coordinate real general", one comment line
// "% surface I NAME AREA" per surface (1-based I, the name percent-encoded where it holds spaces,
// '%' or controls), then "ROWS COLS NONZEROS" and one "I J F_IJ" line per F > 0, 1-based, row
// by row.
absl::Status WriteViewFactorMatrixMarket(const ViewFactorMatrix& matrix, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_VIEWFACTOR_CSV_H_

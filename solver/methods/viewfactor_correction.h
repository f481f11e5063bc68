// Reciprocity and closure enforced on a view-factor matrix (`radiosity viewfactor --enforce`),
// for thermal codes that need both exactly.
//
// With G_ij = A_i F_ij (the exchange areas), reciprocity is G = G^T and closure (a closed
// enclosure) is sum_j G_ij = A_i. "reciprocity" replaces G by its symmetric part (G + G^T) / 2,
// the least-squares symmetric matrix nearest it. "closure" then finds the symmetric correction
// D on the same pattern of nonzero entries that restores every row sum while changing each entry
// least relative to itself: minimise sum_{i<=j} D_ij^2 / G_ij subject to sum_j (G_ij + D_ij) = A_i
// (Lawson 1995; van Leersum 1989). The Lagrange conditions give D_ij = G_ij (l_i + l_j) with
// (diag(G 1) + G) l = A - G 1, a symmetric positive definite system (G >= 0, every row sum > 0)
// solved by Jacobi-preconditioned conjugate gradients. Rows that see nothing are left alone.
#ifndef RADIOSITY_SOLVER_METHODS_VIEWFACTOR_CORRECTION_H_
#define RADIOSITY_SOLVER_METHODS_VIEWFACTOR_CORRECTION_H_

#include <string>

#include "absl/status/statusor.h"
#include "solver/methods/viewfactor.h"

namespace radiosity {

struct ViewFactorCorrection {
  ViewFactorCheck before, after;
  int iterations = 0;         // Conjugate-gradient iterations (closure).
  double smallest_entry = 0;  // The smallest F_ij after the correction (negative: see the README).
};

// Applies `mode` ("reciprocity" or "closure"; "none" does nothing) to `matrix` in place.
// Checks `stop` every iteration (CANCELLED).
absl::StatusOr<ViewFactorCorrection> EnforceViewFactors(ViewFactorMatrix* matrix,
                                                        const std::string& mode,
                                                        const std::atomic<bool>* stop = nullptr);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_VIEWFACTOR_CORRECTION_H_

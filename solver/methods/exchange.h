// Radiative exchange between grey diffuse opaque surfaces from their view factors
// (`radiosity viewfactor --thermal`): Gebhart factors and the net exchange at given temperatures.
//
// Gebhart's absorption factor B_ij is the fraction of the power emitted by surface i that is
// absorbed by surface j, directly or after any number of diffuse reflections (Gebhart 1961; Modest,
// Radiative Heat Transfer, 3rd ed., sec. 5.5). With reflectance rho_k = 1 - eps_k,
//   B_ij = F_ij eps_j + sum_k F_ik rho_k B_kj,   i.e.   (I - F diag(rho)) B = F diag(eps),
// solved here by LU with partial pivoting (every row of F diag(rho) sums to at most 1, so the
// system is regular unless no surface the light can reach absorbs anything).
// Surface i emits E_i = A_i eps_i sigma T_i^4; j absorbs E_i B_ij of it. What no surface absorbs,
// E_i (1 - sum_j B_ij), leaves the scene to the environment, a black enclosure at
// `ambient_temperature`, which by reciprocity (A_i eps_i B_i,env = A_env B_env,i) returns
// A_i eps_i sigma T_env^4 (1 - sum_j B_ij) to surface i. Net exchange of the pair:
// Q_ij = E_i B_ij - E_j B_ji (= A_i eps_i B_ij sigma (T_i^4 - T_j^4) when F is reciprocal).
#ifndef RADIOSITY_SOLVER_METHODS_EXCHANGE_H_
#define RADIOSITY_SOLVER_METHODS_EXCHANGE_H_

#include <atomic>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/methods/viewfactor.h"

namespace radiosity {

// Stefan-Boltzmann constant, W m^-2 K^-4 (CODATA 2018, exact in the SI since 2019).
inline constexpr double kStefanBoltzmann = 5.670374419e-8;
// Surfaces beyond which the dense Gebhart matrix is refused (memory n^2, time n^3).
inline constexpr int kMaxExchangeSurfaces = 8192;

struct RadiantExchange {
  std::vector<std::string> surfaces;  // As in the view-factor matrix.
  std::vector<double> area, emissivity, temperature;
  std::vector<double> gebhart;  // Row-major n x n: gebhart[i * n + j] = B_ij.
  // Per surface, W: emitted E_i; absorbed (from surfaces and the environment); net = emitted -
  // absorbed (the power the surface loses by radiation); to_environment = E_i (1 - sum_j B_ij).
  std::vector<double> emitted, absorbed, net, to_environment, from_environment;
  double ambient_temperature = 0;
  // max over pairs of |A_i eps_i B_ij - A_j eps_j B_ji| / max(both) (pairs with both 0 skipped),
  // and max over surfaces of area > 0 of |1 - sum_j B_ij| (closed enclosures: 0).
  double max_reciprocity_error = 0;
  double max_closure_error = 0;
  double seconds = 0;

  int size() const { return static_cast<int>(surfaces.size()); }
  double b(int i, int j) const { return gebhart[static_cast<size_t>(i) * size() + j]; }
  // Net power from i to j, W: E_i B_ij - E_j B_ji.
  double NetPair(int i, int j) const { return emitted[i] * b(i, j) - emitted[j] * b(j, i); }
};

// ThermalInput (viewfactor.h) holds the emissivities and temperatures.

// OK when the emissivity is in [0, 1] and the temperature finite and >= 0; otherwise
// INVALID_ARGUMENT "surface 'NAME': ...".
absl::Status CheckSurfaceThermal(const SurfaceThermal& t);

// Per-surface emissivity and temperature for the surfaces named `surfaces` (scene order) from
// `input`: every surface must be named or covered by "*", and there may be at most
// kMaxExchangeSurfaces; a name that is not a surface, a repeated name, or a value out of range is
// INVALID_ARGUMENT naming it. Jobs check this before computing the view factors.
absl::StatusOr<std::vector<SurfaceThermal>> ResolveThermal(const std::vector<std::string>& surfaces,
                                                           const ThermalInput& input);

// Gebhart factors and exchange. Fails for more than kMaxExchangeSurfaces surfaces, a singular
// system (FAILED_PRECONDITION) or a stop (CANCELLED; `stop` is checked every pivot row). Runs on
// `threads` threads (0: all cores).
absl::StatusOr<RadiantExchange> ComputeExchange(const ViewFactorMatrix& matrix,
                                                const ThermalInput& input,
                                                const std::atomic<bool>* stop = nullptr,
                                                int threads = 0);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_EXCHANGE_H_

// The method registry: one table of the solution methods, with their names, one-line
// descriptions, the options each reads, the form-factor estimators each takes, and factories. It
// feeds CreateSolver, the CLI's choices and help, the service's validation (Validate,
// IgnoredOptions) and the table of methods in docs/guide/methods.md (tests/docs/check_docs.py
// keeps it equal to `radiosity methods`).
//
// To add a method: implement it behind SolverBase (solver.h) in a file of its own and add a row
// here (registry.cc); `tests/docs/check_docs.py --fix` regenerates the docs' table. The
// parameterised furnace and cancellation tests then run it too.
#ifndef RADIOSITY_SOLVER_METHODS_REGISTRY_H_
#define RADIOSITY_SOLVER_METHODS_REGISTRY_H_

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/methods/solver.h"

namespace radiosity {

struct MethodInfo {
  using Factory = std::function<absl::StatusOr<std::unique_ptr<Solver>>(
      const Scene&, const Mesh&, const Visibility&, const SolveOptions&,
      const std::atomic<bool>* stop)>;

  std::string name;
  std::string description;  // One line, for --help and the docs.
  // Keys (SolveOptionNames) of the options it reads besides the ones every method reads
  // (max_rays, max_seconds, seed, threads). With "formfactor.method" it also reads the options
  // of the estimator (FormFactorEstimators).
  std::vector<std::string> reads;
  // The values of formfactor.method it accepts; the first is what it uses when given the default
  // ("montecarlo"). A request for any other is meaningless (INVALID_ARGUMENT).
  std::vector<std::string> estimators;
  Factory create;

  bool Reads(const std::string& key) const;
  bool Accepts(const std::string& estimator) const;
};

// Every method, in the order the CLI and the docs list them.
const std::vector<MethodInfo>& Methods();
// The method named `name`, or null ("auto" is not a method of its own: method_choice.h).
const MethodInfo* FindMethod(const std::string& name);
// "auto" followed by every method's name: what SolveSpec.method and --method accept.
std::vector<std::string> MethodNames();

// The docs' tables of methods and estimators (Markdown), made from the registry
// (`radiosity methods` prints them).
std::string MethodTables();

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_REGISTRY_H_

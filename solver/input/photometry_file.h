// Photometric files: a luminaire's candela distribution (solver/geometry/photometry.h) from
//  - IES LM-63 (.ies; the 1986, 1991, 1995, 2002 and 2019 revisions): keyword lines, TILT=NONE or
//    TILT=INCLUDE (the tilt table is read and not applied: the luminaire is taken as measured),
//    then numbers separated by blanks, commas or line ends; photometric type C only;
//  - EULUMDAT (.ldt): the fixed line layout, intensities in cd/klm scaled by the lamps' flux.
// Errors are INVALID_ARGUMENT and name the file and line ("lamp.ies:14: ...").
#ifndef RADIOSITY_SOLVER_INPUT_PHOTOMETRY_FILE_H_
#define RADIOSITY_SOLVER_INPUT_PHOTOMETRY_FILE_H_

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "solver/geometry/photometry.h"

namespace radiosity {

// Largest angle counts read (a hostile file cannot make the parser allocate without bound).
inline constexpr int kMaxPhotometryAngles = 10'000;
inline constexpr int64_t kMaxPhotometryValues = 4'000'000;

// `name` is used in messages and as Photometry::source.
absl::StatusOr<Photometry> ParseIes(absl::string_view text, const std::string& name);
absl::StatusOr<Photometry> ParseEulumdat(absl::string_view text, const std::string& name);

// Reads `path` by its extension (.ies or .ldt, any case); `name` in messages (empty: the path).
absl::StatusOr<Photometry> LoadPhotometry(const std::string& path, const std::string& name = "");

// The photometric file `name` among a scene's files in `dir`: a relative name inside it (no
// "..", "." or empty components, not absolute), read with LoadPhotometry; messages name it as
// `shown_dir`/`name` (the client's directory). Errors: INVALID_ARGUMENT for a bad name or file
// (its line), FAILED_PRECONDITION for a file that is not among the scene's.
absl::StatusOr<Photometry> LoadScenePhotometry(const std::string& dir, const std::string& name,
                                               const std::string& shown_dir = "");

// Whether `path` names a photometric file (.ies, .ldt).
bool IsPhotometryFile(const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_PHOTOMETRY_FILE_H_

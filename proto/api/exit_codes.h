// Process exit codes of the radiosity CLI (docs/guide/cli.md). Scripts depend on these values.
#ifndef RADIOSITY_PROTO_API_EXIT_CODES_H_
#define RADIOSITY_PROTO_API_EXIT_CODES_H_

namespace radiosity {

enum ExitCode : int {
  kExitOk = 0,
  kExitInternal = 1,  // A bug or an unexpected failure (Embree error, I/O failure writing results).
  kExitUsage = 2,     // Bad command line: unknown flag, missing argument, value out of range.
  kExitInput = 3,     // Bad input file: unreadable, malformed, or failing validation.
  kExitServer = 4,    // The server could not be reached or answered with an error.
  kExitCancelled = 5,  // The job was cancelled or a deadline passed.
};

}  // namespace radiosity

#endif  // RADIOSITY_PROTO_API_EXIT_CODES_H_

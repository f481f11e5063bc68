// Shell completion for the CLI, generated from its own definition (so it never falls behind a
// new flag): `radiosity completion bash` prints a bash script that completes commands, their
// flags and the global ones (docs/guide/cli.md).
#ifndef RADIOSITY_CLIENT_COMPLETION_H_
#define RADIOSITY_CLIENT_COMPLETION_H_

#include <string>

#include "CLI/CLI.hpp"

namespace radiosity::client {

// A bash completion script for `app` (its subcommands and long options) whose command is
// app.get_name(): COMPREPLY holds the commands before one is given, the flags of the command and
// the global ones after `-`, and file names otherwise.
std::string BashCompletion(const CLI::App& app);

}  // namespace radiosity::client

#endif  // RADIOSITY_CLIENT_COMPLETION_H_

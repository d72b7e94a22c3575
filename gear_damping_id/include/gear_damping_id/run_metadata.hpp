// Run metadata for the `analyze` JSON (`metadata`): what produced a result, for the report's
// header and for anyone reading a result file months later. No ROS.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace gear_damping_id {

/// {package, version, command_line (shell-quoted), argv, working_directory, date (UTC, ISO
/// 8601), input {path, absolute_path, size_bytes, modified (UTC, ISO 8601)}, options}.
/// `options` is stored as given (the options set on the command line). No content hash is
/// computed here (reading a 500 MB bag twice would double the run time): the report hashes the
/// input (SHA-256) when it can still read it and its size and modification time are unchanged.
/// A missing input file gives null size and time.
nlohmann::json runMetadata(const std::vector<std::string>& argv, const std::string& input,
                           const nlohmann::json& options, const std::string& version);

/// `arg` quoted for a POSIX shell when it needs it (spaces, quotes, $, ...), as is otherwise.
std::string shellQuote(const std::string& arg);

}  // namespace gear_damping_id

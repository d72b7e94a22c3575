#include "gear_damping_id/run_metadata.hpp"

#include <sys/stat.h>

#include <ctime>
#include <filesystem>

namespace gear_damping_id {
namespace {

std::string isoUtc(std::time_t t) {
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

}  // namespace

std::string shellQuote(const std::string& arg) {
  if (!arg.empty() && arg.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                            "0123456789_-+=/.,:@%") == std::string::npos)
    return arg;
  std::string q = "'";
  for (char ch : arg) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

nlohmann::json runMetadata(const std::vector<std::string>& argv, const std::string& input,
                           const nlohmann::json& options, const std::string& version) {
  namespace fs = std::filesystem;
  std::string line;
  for (const auto& a : argv) line += (line.empty() ? "" : " ") + shellQuote(a);
  std::error_code ec;
  const fs::path abs = fs::absolute(input, ec);
  const std::string cwd = fs::current_path(ec).string();
  nlohmann::json in = {{"path", input},
                       {"absolute_path", abs.string()},
                       {"size_bytes", nullptr},
                       {"modified", nullptr}};
  struct stat st {};
  if (::stat(input.c_str(), &st) == 0) {
    in["size_bytes"] = static_cast<std::int64_t>(st.st_size);
    in["modified"] = isoUtc(st.st_mtime);
    in["modified_unix"] = static_cast<std::int64_t>(st.st_mtime);
  }
  return {{"package", "gear_damping"},
          {"version", version},
          {"command_line", line},
          {"argv", argv},
          {"working_directory", cwd},
          {"date", isoUtc(std::time(nullptr))},
          {"input", in},
          {"options", options}};
}

}  // namespace gear_damping_id

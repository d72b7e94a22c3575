// How the package's error messages show user data and numbers: text from files and command
// lines is quoted escaped and truncated (binary garbage or a 10 MB line never reaches the
// terminal raw), doubles are printed with enough digits to read back the same value (two
// different times never print alike, as with std::to_string's 6 decimals). No ROS.
#pragma once

#include <charconv>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace gear_sim {

/// The longest excerpt of user data a message shows [printable characters].
constexpr std::size_t kMaxQuotedChars = 80;

/// `text` in single quotes, printable ASCII kept, everything else escaped (\n, \t, \xNN), a
/// UTF-8 byte-order mark named as <BOM>, cut after `max_chars` output characters with
/// "... (N bytes)" appended.
inline std::string quoteForMessage(std::string_view text, std::size_t max_chars = kMaxQuotedChars) {
  std::string out = "'";
  std::size_t shown = 0, i = 0;
  static const char* kHex = "0123456789abcdef";
  for (; i < text.size() && shown < max_chars; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    std::string piece;
    if (c == 0xEF && text.substr(i, 3) == "\xEF\xBB\xBF") {
      piece = "<BOM>";
      i += 2;
    } else if (c == '\\' || c == '\'') {
      piece = std::string("\\") + static_cast<char>(c);
    } else if (c >= 0x20 && c < 0x7F) {
      piece = std::string(1, static_cast<char>(c));
    } else if (c == '\n') {
      piece = "\\n";
    } else if (c == '\t') {
      piece = "\\t";
    } else if (c == '\r') {
      piece = "\\r";
    } else {
      piece = std::string("\\x") + kHex[c >> 4] + kHex[c & 15];
    }
    out += piece;
    shown += piece.size();
  }
  out += "'";
  if (i < text.size()) out += "... (" + std::to_string(text.size()) + " bytes)";
  return out;
}

/// The shortest text that reads back to exactly `x` ("1e-06", "6.0000001e-06", "nan", "inf").
inline std::string formatNumber(double x) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, x);
  return std::string(buf, r.ptr);
}

}  // namespace gear_sim

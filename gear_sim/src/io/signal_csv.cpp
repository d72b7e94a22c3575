#include "gear_sim/signal_csv.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string_view>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

const std::vector<std::string>& signalColumnNames() {
  static const std::vector<std::string> names{"time",   "dte",        "dte_velocity", "stiffness",
                                              "torque", "mesh_state", "mesh_phase",   "damping",
                                              "theta1", "theta2"};
  return names;
}

namespace {

// The column vectors of a table in canonical order (matches signalColumnNames()).
std::vector<Eigen::VectorXd*> columns(SignalTable& t) {
  return {&t.time,       &t.dte,        &t.dte_velocity, &t.stiffness, &t.torque,
          &t.mesh_state, &t.mesh_phase, &t.damping,      &t.theta1,    &t.theta2};
}

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

enum class LineRead { Ok, End, TooLong };

// std::getline with a length limit: a file without newlines (/dev/zero, binary garbage) is
// refused after kMaxCsvLineBytes instead of being read into memory whole.
LineRead readLine(std::istream& f, std::vector<char>& buf, std::string* line) {
  f.getline(buf.data(), static_cast<std::streamsize>(buf.size()));
  const std::streamsize n = f.gcount();
  if (f.fail() && !f.eof() && !f.bad() && n + 1 >= static_cast<std::streamsize>(buf.size()))
    return LineRead::TooLong;
  if (f.bad() || (n == 0 && f.eof())) return LineRead::End;
  line->assign(buf.data(), static_cast<size_t>(f.eof() ? n : n - 1));
  return LineRead::Ok;
}

}  // namespace

Status writeSignalCsv(const std::string& path, const SignalTable& table) {
  SignalTable& t = const_cast<SignalTable&>(table);  // columns() only reads through it here
  const auto cols = columns(t);
  const auto& names = signalColumnNames();
  std::vector<const Eigen::VectorXd*> present;
  std::string header;
  for (size_t c = 0; c < cols.size(); ++c) {
    if (c >= 2 && cols[c]->size() == 0) continue;
    if (cols[c]->size() != table.time.size())
      return Status::invalidInput("column " + names[c] + " has " + std::to_string(cols[c]->size()) +
                                      " values, time has " + std::to_string(table.time.size()),
                                  names[c]);
    present.push_back(cols[c]);
    header += (header.empty() ? "" : ",") + names[c];
  }
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Status::ioError(path + ": cannot open for writing");
  std::fputs((header + "\n").c_str(), f.get());
  std::string line;
  char buf[32];
  for (Eigen::Index i = 0; i < table.time.size(); ++i) {
    line.clear();
    for (size_t c = 0; c < present.size(); ++c) {
      if (c) line += ',';
      const auto r = std::to_chars(buf, buf + sizeof buf, (*present[c])[i]);
      line.append(buf, r.ptr);
    }
    line += '\n';
    std::fwrite(line.data(), 1, line.size(), f.get());
  }
  if (std::fflush(f.get()) != 0 || std::ferror(f.get()))
    return Status::ioError(path + ": write failed");
  return {};
}

namespace {

// An existing file that is neither regular nor a directory: written in place, never renamed over.
bool isSpecialFile(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode);
}

// Copies the bytes of `from` into `to` (opened for writing, not created), 64 KiB at a time.
bool copyInto(const std::string& from, const std::string& to) {
  std::unique_ptr<FILE, int (*)(FILE*)> in(std::fopen(from.c_str(), "rb"), &std::fclose);
  std::unique_ptr<FILE, int (*)(FILE*)> out(std::fopen(to.c_str(), "wb"), &std::fclose);
  if (!in || !out) return false;
  std::vector<char> buf(size_t{1} << 16);
  for (size_t n; (n = std::fread(buf.data(), 1, buf.size(), in.get())) > 0;) {
    if (std::fwrite(buf.data(), 1, n, out.get()) != n) return false;
  }
  return !std::ferror(in.get()) && std::fflush(out.get()) == 0;
}

}  // namespace

Result<std::string> partialPath(const std::string& path) {
  if (!isSpecialFile(path)) return path + ".partial";
  std::error_code ec;
  std::string tmp = (std::filesystem::temp_directory_path(ec) / "gear_damping_XXXXXX").string();
  const int fd = ec ? -1 : ::mkstemp(tmp.data());
  if (fd < 0) return Status::ioError(path + ": cannot create a temporary file to write it");
  ::close(fd);
  return tmp;
}

Status commitFile(const std::string& tmp, const std::string& path) {
  if (isSpecialFile(path)) {  // copy: a rename would replace the device or FIFO itself
    const bool ok = copyInto(tmp, path);
    std::remove(tmp.c_str());
    return ok ? Status() : Status::ioError(path + ": cannot write");
  }
  if (std::rename(tmp.c_str(), path.c_str()) == 0) return {};
  std::remove(tmp.c_str());
  return Status::ioError(path + ": cannot write");
}

Status writeAtomically(const std::string& path,
                       const std::function<Status(const std::string& tmp)>& write) {
  const Result<std::string> tmp = partialPath(path);
  if (!tmp.ok()) return tmp.status();
  Status s = write(*tmp);
  if (s.ok()) s = commitFile(*tmp, path);  // (removes the file itself when it fails)
  if (!s.ok()) std::remove(tmp->c_str());
  return s;
}

namespace {

// std::from_chars of a CSV field, and what it refuses that is still a number: an explicit plus
// sign (as spreadsheets write it) and a number beyond the double range, read as +-Inf for an
// overflow (then refused, or read as NaN like "inf"), +-0 for an underflow (a negative
// exponent, or no exponent and a zero integer part).
std::from_chars_result parseNumber(const char* p, const char* end, double* v) {
  const char* num = p + 1 < end && *p == '+' && p[1] != '+' && p[1] != '-' ? p + 1 : p;
  std::from_chars_result r = std::from_chars(num, end, *v);
  if (r.ec != std::errc::result_out_of_range) return r;
  const std::string_view s(num, static_cast<size_t>(r.ptr - num));
  const size_t e = s.find_first_of("eE");
  const bool negative = !s.empty() && s[0] == '-';
  const std::string_view mantissa = s.substr(negative ? 1 : 0, e - (negative ? 1 : 0));
  const size_t lead = std::min(mantissa.find_first_not_of('0'), mantissa.size());
  const bool under = e != std::string_view::npos ? e + 1 < s.size() && s[e + 1] == '-'
                                                 : lead == mantissa.size() || mantissa[lead] == '.';
  *v = under ? 0.0 : std::numeric_limits<double>::infinity();
  if (negative) *v = -*v;
  r.ec = std::errc();
  return r;
}

}  // namespace

Status readSignalCsv(const std::string& path, SignalTable* out,
                     const std::vector<std::string>& required, bool allow_non_finite) {
  // Every failure past opening is the file's content; `column` names the CSV column concerned.
  auto fail = [&](const std::string& what, const std::string& column = {}) {
    return Status::invalidInput(path + ": " + what, column);
  };
  std::ifstream f(path);
  if (!f) return Status::ioError(path + ": cannot open");
  std::string line;
  long line_no = 0;
  std::vector<char> buf(kMaxCsvLineBytes + 1);
  LineRead got = LineRead::End;
  auto tooLong = [&]() {
    return fail("line " + std::to_string(line_no + 1) + ": longer than " +
                std::to_string(kMaxCsvLineBytes) + " bytes (not a signal CSV?)");
  };
  // Header: the first non-empty line (a UTF-8 byte-order mark before it is skipped).
  while ((got = readLine(f, buf, &line)) == LineRead::Ok) {
    ++line_no;
    if (line_no == 1 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);
    if (!trim(line).empty()) break;
  }
  if (got == LineRead::TooLong) return tooLong();
  if (trim(line).empty()) return fail("empty file (no header row)");
  const auto& names = signalColumnNames();
  std::vector<int> map;  // field -> canonical column
  {
    std::stringstream ss(line);
    std::string name;
    int field = 0;
    std::vector<bool> seen(names.size(), false);
    while (std::getline(ss, name, ',')) {
      ++field;
      name = trim(name);
      size_t c = 0;
      while (c < names.size() && names[c] != name) ++c;
      if (c == names.size()) {
        std::string list;
        for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
        return fail("line " + std::to_string(line_no) + ", column " + std::to_string(field) +
                        ": unknown column " + quoteForMessage(name) + " (known: " + list + ")",
                    name);
      }
      if (seen[c])
        return fail(
            "line " + std::to_string(line_no) + ": duplicate column " + quoteForMessage(name),
            name);
      seen[c] = true;
      map.push_back(static_cast<int>(c));
    }
    for (const auto& r : required) {
      size_t c = 0;
      while (c < names.size() && names[c] != r) ++c;
      if (c == names.size() || !seen[c])
        return fail("missing required column " + quoteForMessage(r), r);
    }
  }
  std::vector<std::vector<double>> data(names.size());
  std::vector<long> row_line;  // file line of each data row, for messages
  while ((got = readLine(f, buf, &line)) == LineRead::Ok) {
    ++line_no;
    if (trim(line).empty()) continue;
    row_line.push_back(line_no);
    const char* p = line.data();
    const char* end = p + line.size();
    while (end > p && (end[-1] == '\r' || end[-1] == ' ')) --end;
    for (size_t field = 0; field < map.size(); ++field) {
      while (p < end && *p == ' ') ++p;
      double v;
      const auto r = parseNumber(p, end, &v);
      const std::string where = "line " + std::to_string(line_no) + ", column " +
                                std::to_string(field + 1) + " (" + names[map[field]] + ")";
      if (r.ec != std::errc() || (r.ptr < end && *r.ptr != ',' && *r.ptr != ' ')) {
        const char* q = p;
        while (q < end && *q != ',') ++q;
        return fail(where + ": malformed number " + quoteForMessage(std::string_view(p, q - p)),
                    names[map[field]]);
      }
      if (!std::isfinite(v) && (!allow_non_finite || map[field] == 0))
        return fail(where + ": value is not finite (" + formatNumber(v) + ")", names[map[field]]);
      data[map[field]].push_back(v);
      p = r.ptr;
      while (p < end && *p == ' ') ++p;
      if (field + 1 < map.size()) {
        if (p >= end || *p != ',')
          return fail("line " + std::to_string(line_no) + ": " + std::to_string(field + 1) +
                      " fields, the header has " + std::to_string(map.size()));
        ++p;
      } else if (p != end) {
        return fail("line " + std::to_string(line_no) + ": more fields than the header's " +
                    std::to_string(map.size()));
      }
    }
  }
  if (got == LineRead::TooLong) return tooLong();
  const std::vector<double>& time = data[0];
  if (time.size() < 2) return fail("fewer than two data rows");
  for (size_t i = 1; i < time.size(); ++i)
    if (!(time[i] > time[i - 1]))
      return fail("line " + std::to_string(row_line[i]) + ": time " + formatNumber(time[i]) +
                      " is not greater than the previous " + formatNumber(time[i - 1]) +
                      " (time must be strictly increasing)",
                  "time");
  SignalTable t;
  const auto cols = columns(t);
  for (size_t c = 0; c < names.size(); ++c)
    if (!data[c].empty())
      *cols[c] = Eigen::Map<const Eigen::VectorXd>(data[c].data(), data[c].size());
  *out = std::move(t);
  return {};
}

}  // namespace gear_sim

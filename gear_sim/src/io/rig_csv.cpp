#include "gear_sim/rig_csv.hpp"

#include <charconv>
#include <cstdio>
#include <fstream>

#include "gear_sim/signal_csv.hpp"

namespace gear_sim {

namespace {
void put(std::string* line, double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  line->append(buf, r.ptr);
}
// Writes `header` and the rows row(i), i < n, to `path`; IoError when it cannot.
template <class Row>
Status writeRows(const std::string& path, const char* header, Eigen::Index n, Row&& row) {
  std::ofstream f(path);
  if (f) {
    f << header;
    std::string line;
    for (Eigen::Index i = 0; i < n; ++i) {
      line.clear();
      row(i, &line);
      line += '\n';
      f << line;
    }
    f.close();
  }
  if (!f) return Status::ioError(path + ": cannot write");
  return {};
}

}  // namespace

Status writeRigCsv(const std::string& path, const SignalTable& t) {
  const Eigen::Index n = t.size();
  const bool torque = t.torque.size() == n;
  if (t.theta1.size() != n || t.theta2.size() != n)
    return Status::invalidInput(path + ": a rig record needs theta1 and theta2 as long as time",
                                t.theta1.size() != n ? "theta1" : "theta2");
  return writeRows(path, torque ? "time,theta1,theta2,torque\n" : "time,theta1,theta2\n", n,
                   [&](Eigen::Index i, std::string* line) {
                     put(line, t.time[i]);
                     *line += ',';
                     put(line, t.theta1[i]);
                     *line += ',';
                     put(line, t.theta2[i]);
                     if (torque) {
                       *line += ',';
                       put(line, t.torque[i]);
                     }
                   });
}

bool isRigCsv(const std::string& path) {
  std::ifstream f(path);
  std::string header;
  if (!f || !std::getline(f, header)) return false;
  if (header.rfind("\xEF\xBB\xBF", 0) == 0) header.erase(0, 3);
  std::vector<std::string> cols;
  std::string cur;
  for (char ch : header) {
    if (ch == ',') {
      cols.push_back(cur);
      cur.clear();
    } else if (ch != ' ' && ch != '\r' && ch != '\t') {
      cur += ch;
    }
  }
  cols.push_back(cur);
  bool t1 = false, t2 = false, dte = false;
  for (const auto& c : cols) t1 |= c == "theta1", t2 |= c == "theta2", dte |= c == "dte";
  return t1 && t2 && !dte;
}

Status readRigCsv(const std::string& path, SignalTable* out) {
  if (Status s = readSignalCsv(path, out, {"time", "theta1", "theta2"}); !s.ok()) return s;
  if (out->dte.size() > 0)
    return Status::invalidInput(path + ": has a dte column: an ordinary record, not a rig record",
                                "dte");
  return {};
}

Status writeEdgeCsv(const std::string& path, const std::vector<double>& edges) {
  return writeRows(
      path, "time\n", static_cast<Eigen::Index>(edges.size()),
      [&](Eigen::Index i, std::string* line) { put(line, edges[static_cast<size_t>(i)]); });
}

Status readEdgeCsv(const std::string& path, std::vector<double>* edges) {
  SignalTable t;
  if (Status s = readSignalCsv(path, &t, {"time"}); !s.ok()) return s;
  if (t.dte.size() > 0 || t.theta1.size() > 0 || t.theta2.size() > 0 || t.torque.size() > 0)
    return Status::invalidInput(path + ": an edge-time file has the one column time");
  edges->assign(t.time.data(), t.time.data() + t.time.size());
  return {};
}

}  // namespace gear_sim

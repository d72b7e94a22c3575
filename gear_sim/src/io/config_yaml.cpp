#include "gear_sim/config_yaml.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <variant>
#include <vector>

#include "gear_sim/message_text.hpp"
#include "gear_sim/signal_csv.hpp"

namespace gear_sim {
namespace {

// A YAML node as the text the file had (escaped and truncated for a message).
std::string quoted(const YAML::Node& n) {
  std::ostringstream os;
  os << n;
  return quoteForMessage(os.str());
}

// A key as a message names it: as is when it is a plain name (letters, digits, '_', at most
// kMaxQuotedChars), else quoted escaped and truncated.
std::string keyForMessage(const std::string& key) {
  const bool plain = !key.empty() && key.size() <= kMaxQuotedChars &&
                     std::all_of(key.begin(), key.end(), [](char c) {
                       return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
                     });
  return plain ? key : quoteForMessage(key);
}

// A mapping key for a message and a lookup: its name when it is a scalar; a sequence or a
// mapping used as a key (`? [a, b]`) is an error naming it, not an exception.
Result<std::string> keyName(const YAML::Node& key, const std::string& where) {
  if (key.IsScalar()) return key.Scalar();
  return Status::invalidInput(where + quoted(key) +
                              ": a key must be a plain name, not a sequence or mapping");
}

// Reads one section: checks its keys against the known list and converts values, recording
// the first error with the full key name (message and Status::field()).
class Section {
 public:
  // (Copy-constructed: assigning a missing child to an existing YAML::Node throws.)
  Section(const YAML::Node& root, const std::string& name, Status* status)
      : name_(name), status_(status), node_(root[name]) {
    if (node_ && !node_.IsMap()) fail(name_, "must be a mapping of keys");
  }
  bool present() const { return node_ && node_.IsMap(); }

  // Every key of the section must be in `known`.
  void allow(const std::vector<std::string>& known) {
    if (!present() || !ok()) return;
    std::set<std::string> k(known.begin(), known.end());
    for (const auto& kv : node_) {
      const Result<std::string> name = keyName(kv.first, name_ + ".");
      if (!name.ok()) {
        if (ok()) *status_ = name.status();
        return;
      }
      const std::string& key = *name;
      if (!k.count(key)) {
        std::string list;
        for (const std::string& s : known) list += (list.empty() ? "" : ", ") + s;
        fail(name_ + "." + keyForMessage(key), "unknown key (known: " + list + ")");
        return;
      }
    }
  }

  template <class T>
  void get(const char* key, T* out) {
    if (!present() || !ok() || !node_[key]) return;
    try {
      *out = node_[key].as<T>();
    } catch (const YAML::Exception&) {
      fail(name_ + "." + key,
           std::string("expected ") + typeName<T>() + ", got " + quoted(node_[key]));
    }
  }

  // An enum by name, through gear_sim::parse.
  template <class E>
  void getEnum(const char* key, E* out, const char* names) {
    std::string s;
    if (!present() || !ok() || !node_[key]) return;
    get(key, &s);
    if (ok() && !parse(s, out))
      fail(name_ + "." + key, "unknown name " + quoteForMessage(s) + " (one of: " + names + ")");
  }

  bool has(const char* key) const { return present() && node_[key]; }
  void fail(const std::string& key, const std::string& what) {
    if (ok()) *status_ = Status::invalidInput(key + ": " + what, key);
  }
  bool ok() const { return status_->ok(); }

 private:
  template <class T>
  static const char* typeName() {
    if constexpr (std::is_same_v<T, double>) return "a number";
    if constexpr (std::is_integral_v<T>) return "an integer";
    if constexpr (std::is_same_v<T, std::string>) return "a string";
    return "a list of numbers";
  }
  std::string name_;
  Status* status_;
  const YAML::Node node_;
};

// The plain (number, integer, list) keys of a section and the members they set: the one key
// list that loadSimConfig reads and toYaml writes. Enum-valued and special keys are handled by
// their section's reader and writer.
template <class S>
struct Key {
  const char* name;
  std::variant<double S::*, std::vector<double> S::*, int S::*, unsigned long S::*> member;
};

const Key<Gear> kGearKeys[] = {
    {"teeth", &Gear::teeth}, {"inertia", &Gear::inertia}, {"base_radius", &Gear::base_radius}};
const Key<MeshOptions> kMeshKeys[] = {{"k_max", &MeshOptions::k_max},
                                      {"k_min", &MeshOptions::k_min},
                                      {"contact_ratio", &MeshOptions::contact_ratio},
                                      {"transition_fraction", &MeshOptions::transition_fraction},
                                      {"k_mean", &MeshOptions::k_mean},
                                      {"fourier_cos", &MeshOptions::fourier_cos},
                                      {"fourier_sin", &MeshOptions::fourier_sin},
                                      {"initial_phase", &MeshOptions::initial_phase}};
const Key<SpeedOptions> kSpeedKeys[] = {{"pinion_rpm", &SpeedOptions::pinion_rpm},
                                        {"end_rpm", &SpeedOptions::end_rpm},
                                        {"ramp_time", &SpeedOptions::ramp_time}};
const Key<LoadOptions> kLoadKeys[] = {
    {"mean", &LoadOptions::mean},           {"amplitude", &LoadOptions::amplitude},
    {"frequency", &LoadOptions::frequency}, {"phase", &LoadOptions::phase},
    {"initial", &LoadOptions::initial},     {"final", &LoadOptions::final_value},
    {"step_time", &LoadOptions::step_time}, {"ramp_start", &LoadOptions::ramp_start},
    {"ramp_end", &LoadOptions::ramp_end},   {"low", &LoadOptions::low},
    {"high", &LoadOptions::high},           {"period", &LoadOptions::period},
    {"rise", &LoadOptions::rise},           {"hold", &LoadOptions::hold},
    {"fall", &LoadOptions::fall},           {"times", &LoadOptions::times},
    {"values", &LoadOptions::values}};
const Key<DampingOptions> kDampingKeys[] = {{"load_sensitivity", &DampingOptions::load_sensitivity},
                                            {"times", &DampingOptions::times},
                                            {"ratios", &DampingOptions::ratios},
                                            {"c0", &DampingOptions::c0},
                                            {"c1", &DampingOptions::c1}};
const Key<SimulationOptions> kSimulationKeys[] = {
    {"duration", &SimulationOptions::duration},
    {"sample_rate", &SimulationOptions::sample_rate},
    {"substeps", &SimulationOptions::substeps},
    {"initial_dte", &SimulationOptions::initial_dte},
    {"initial_velocity", &SimulationOptions::initial_velocity},
    {"noise_snr_db", &SimulationOptions::noise_snr_db},
    {"seed", &SimulationOptions::seed}};
const Key<SteOptions> kSteKeys[] = {
    {"offset", &SteOptions::offset},         {"mesh_cos", &SteOptions::mesh_cos},
    {"mesh_sin", &SteOptions::mesh_sin},     {"pinion_cos", &SteOptions::pinion_cos},
    {"pinion_sin", &SteOptions::pinion_sin}, {"gear_cos", &SteOptions::gear_cos},
    {"gear_sin", &SteOptions::gear_sin}};

// `before`, the names of `keys`, then `after`: a section's allowed keys.
template <class S, size_t N>
std::vector<std::string> keyNames(std::initializer_list<const char*> before,
                                  const Key<S> (&keys)[N],
                                  std::initializer_list<const char*> after = {}) {
  std::vector<std::string> out(before.begin(), before.end());
  for (const Key<S>& k : keys) out.push_back(k.name);
  out.insert(out.end(), after.begin(), after.end());
  return out;
}

template <class S>
void readKey(Section& s, const Key<S>& k, S* out) {
  std::visit([&](auto m) { s.get(k.name, &(out->*m)); }, k.member);
}

template <class S, size_t N>
void readKeys(Section& s, const Key<S> (&keys)[N], S* out) {
  for (const Key<S>& k : keys) readKey(s, k, out);
}

template <class S, size_t N>
void writeKeys(const Key<S> (&keys)[N], const S& in, YAML::Node node) {
  for (const Key<S>& k : keys) std::visit([&](auto m) { node[k.name] = in.*m; }, k.member);
}

void readGear(Section& s, Gear* g) {
  s.allow(keyNames({}, kGearKeys));
  readKeys(s, kGearKeys, g);
}

void readMesh(Section& s, MeshOptions* m) {
  s.allow(keyNames({"stiffness_model"}, kMeshKeys));
  s.getEnum("stiffness_model", &m->model, "square, trapezoid, fourier, constant");
  readKeys(s, kMeshKeys, m);
}

void readSpeed(Section& s, SpeedOptions* o) {
  s.allow(keyNames({"profile"}, kSpeedKeys));
  s.getEnum("profile", &o->profile, "constant, ramp");
  readKeys(s, kSpeedKeys, o);
  if (!s.has("end_rpm")) o->end_rpm = o->pinion_rpm;  // a constant speed unless given
}

// load.profile csv: a CSV file with columns time [s] and torque [N*m] becomes a piecewise-linear
// table; `base_dir` resolves a relative load.file.
void readLoadCsv(Section& l, const std::string& base_dir, LoadOptions* o) {
  std::string file;
  l.get("file", &file);
  if (l.ok() && file.empty()) l.fail("load.file", "required with load.profile = csv");
  if (!l.ok()) return;
  const std::string path = (!file.empty() && file[0] == '/') ? file : base_dir + "/" + file;
  SignalTable t;
  if (const Status read = readTorqueCsv(path, &t); !read.ok()) {
    std::string e = read.message();
    // The path comes from the file: quoted in the message (the reader's starts with it).
    if (e.compare(0, path.size(), path) == 0) e = quoteForMessage(path) + e.substr(path.size());
    l.fail("load.file", e);
    return;
  }
  o->profile = LoadProfile::Table;
  o->times.assign(t.time.data(), t.time.data() + t.time.size());
  o->values.assign(t.torque.data(), t.torque.data() + t.torque.size());
}

void readLoad(const YAML::Node& root, const std::string& base_dir, Status* err, LoadOptions* o) {
  Section l(root, "load", err);
  l.allow(keyNames({"profile"}, kLoadKeys, {"file"}));
  std::string profile = "sine";
  l.get("profile", &profile);
  if (profile == "csv") {
    readLoadCsv(l, base_dir, o);
  } else if (l.ok() && !parse(profile, &o->profile)) {
    l.fail("load.profile", "unknown name " + quoteForMessage(profile) +
                               " (one of: constant, sine, step, ramp, trapezoid, table, csv)");
  }
  for (const Key<LoadOptions>& k : kLoadKeys)  // csv: times and values come from the file
    if (profile != "csv" || std::holds_alternative<double LoadOptions::*>(k.member))
      readKey(l, k, o);
}

void readDamping(const YAML::Node& root, Status* err, DampingOptions* o) {
  Section d(root, "damping", err);
  d.allow(keyNames({"model", "ratio", "coefficient"}, kDampingKeys));
  std::string model = "load_dependent";
  d.get("model", &model);
  if (model == "constant") {
    if (d.has("ratio") && d.has("coefficient"))
      d.fail("damping.coefficient", "give either damping.ratio or damping.coefficient, not both");
    o->model =
        d.has("coefficient") ? DampingProfile::ConstantCoefficient : DampingProfile::ConstantRatio;
  } else if (model == "piecewise") {
    o->model = DampingProfile::Piecewise;
  } else if (model == "load_dependent") {
    o->model = DampingProfile::LoadDependent;
  } else if (model == "load_linear") {
    o->model = DampingProfile::LoadLinear;
  } else {
    d.fail("damping.model", "unknown name " + quoteForMessage(model) +
                                " (one of: constant, piecewise, load_dependent, load_linear)");
  }
  d.get("ratio", &o->ratio);
  d.get("coefficient", &o->coefficient);
  readKeys(d, kDampingKeys, o);
}

void readSimulation(const YAML::Node& root, Status* err, SimulationOptions* o) {
  Section s(root, "simulation", err);
  s.allow(keyNames({"integrator", "dynamics"}, kSimulationKeys));
  s.getEnum("integrator", &o->integrator, "rk2, rk4");
  s.getEnum("dynamics", &o->dynamics, "reduced, torsional");
  readKeys(s, kSimulationKeys, o);
}

// Static transmission error (docs/ste.md): absent = none.
void readSte(const YAML::Node& root, Status* err, SteOptions* o) {
  Section st(root, "ste", err);
  st.allow(keyNames({}, kSteKeys, {"damping"}));
  readKeys(st, kSteKeys, o);
  std::string ste_damping = steDampingName(o->damping);
  st.get("damping", &ste_damping);
  if (!st.ok()) return;
  if (const Result<SteDamping> d = parseSteDamping(ste_damping); d.ok())
    o->damping = *d;
  else
    st.fail("ste.damping", d.status().message());
}

// `encoder` is read by loadEncoderOptions (encoder_yaml.hpp).
void checkSections(const YAML::Node& root, Status* err) {
  const std::set<std::string> sections{"pinion",  "gear",       "mesh", "speed",  "load",
                                       "damping", "simulation", "ste",  "encoder"};
  for (const auto& kv : root) {
    const Result<std::string> name = keyName(kv.first, "");
    if (!name.ok()) {
      *err = name.status();
      return;
    }
    const std::string& key = *name;
    if (!sections.count(key)) {
      *err = Status::invalidInput(
          keyForMessage(key) +
              ": unknown section (known: pinion, gear, mesh, speed, load, damping, simulation, "
              "ste, encoder)",
          key);
      return;
    }
  }
}

// pinion, gear, mesh and speed into `m`.
void readGearModel(const YAML::Node& root, Status* err, GearModel* m) {
  Section p(root, "pinion", err), g(root, "gear", err), me(root, "mesh", err),
      sp(root, "speed", err);
  readGear(p, &m->gears.pinion);
  readGear(g, &m->gears.gear);
  readMesh(me, &m->mesh);
  readSpeed(sp, &m->speed);
}

std::string dirOf(const std::string& path) {
  const size_t p = path.find_last_of('/');
  return p == std::string::npos ? "." : path.substr(0, p);
}

}  // namespace

static Status loadGearModelImpl(const YAML::Node& root, GearModel* out) {
  if (!root || !root.IsMap())
    return Status::invalidInput("the parameter file must be a YAML mapping of sections");
  for (const char* sec : {"pinion", "gear", "mesh", "speed"})
    if (!root[sec])
      return Status::invalidInput(
          std::string(sec) + ": missing section (pinion, gear, mesh and speed are required)", sec);
  GearModel m;
  Status err;
  readGearModel(root, &err, &m);
  if (err.ok()) err = m.check();
  if (err.ok()) *out = m;
  return err;
}

static Status loadSimConfigImpl(const YAML::Node& root, SimConfig* out,
                                const std::string& base_dir) {
  if (!root || !root.IsMap())
    return Status::invalidInput("the configuration must be a YAML mapping of sections");
  Status err;
  SimConfig c;
  checkSections(root, &err);
  if (err.ok()) {
    GearModel m = c.gearModel();
    readGearModel(root, &err, &m);
    c.gears = m.gears;
    c.mesh = m.mesh;
    c.speed = m.speed;
    readLoad(root, base_dir, &err, &c.load);
    readDamping(root, &err, &c.damping);
    readSimulation(root, &err, &c.simulation);
    readSte(root, &err, &c.ste);
  }
  if (err.ok()) err = c.check();
  if (err.ok()) *out = c;
  return err;
}

// yaml-cpp throws on some malformed documents the checks above do not foresee (a conversion of
// an unusual node): every such exception becomes an error, never an abort.
Status loadGearModel(const YAML::Node& root, GearModel* out) {
  try {
    return loadGearModelImpl(root, out);
  } catch (const YAML::Exception& e) {
    return Status::invalidInput("malformed YAML: " + quoteForMessage(e.what()));
  }
}

Status loadSimConfig(const YAML::Node& root, SimConfig* out, const std::string& base_dir) {
  try {
    return loadSimConfigImpl(root, out, base_dir);
  } catch (const YAML::Exception& e) {
    return Status::invalidInput("malformed YAML: " + quoteForMessage(e.what()));
  }
}

namespace {
Result<YAML::Node> loadFile(const std::string& path) {
  // A regular file only: a directory opens as a stream whose first read throws (a hostile test
  // of wavelet_node's ~gear_config: the node aborted instead of naming the parameter), a FIFO
  // blocks, /dev/zero is read until memory runs out.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return Status::ioError(path + ": is a directory");
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec))
    return Status::ioError(path + ": not a regular file");
  std::ifstream f(path);
  if (!f) return Status::ioError(path + ": cannot open");
  try {
    return YAML::Load(f);
  } catch (const YAML::Exception& e) {
    return Status::invalidInput(path + ": YAML syntax error at line " +
                                std::to_string(e.mark.line + 1) + ": " + quoteForMessage(e.msg));
  } catch (const std::ios_base::failure& e) {
    return Status::ioError(path + ": cannot read (" + quoteForMessage(e.what()) + ")");
  }
}
}  // namespace

Status loadSimConfigFile(const std::string& path, SimConfig* out) {
  const Result<YAML::Node> root = loadFile(path);
  if (!root.ok()) return root.status();
  return loadSimConfig(*root, out, dirOf(path)).withContext(path);
}

Status loadGearModelFile(const std::string& path, GearModel* out) {
  const Result<YAML::Node> root = loadFile(path);
  if (!root.ok()) return root.status();
  return loadGearModel(*root, out).withContext(path);
}

YAML::Node toYaml(const SimConfig& c) {
  YAML::Node n;
  writeKeys(kGearKeys, c.gears.pinion, n["pinion"]);
  writeKeys(kGearKeys, c.gears.gear, n["gear"]);
  n["mesh"]["stiffness_model"] = toString(c.mesh.model);
  writeKeys(kMeshKeys, c.mesh, n["mesh"]);
  n["speed"]["profile"] = toString(c.speed.profile);
  writeKeys(kSpeedKeys, c.speed, n["speed"]);
  n["load"]["profile"] = toString(c.load.profile);
  writeKeys(kLoadKeys, c.load, n["load"]);
  const DampingOptions& d = c.damping;
  const char* model = d.model == DampingProfile::Piecewise       ? "piecewise"
                      : d.model == DampingProfile::LoadDependent ? "load_dependent"
                      : d.model == DampingProfile::LoadLinear    ? "load_linear"
                                                                 : "constant";
  n["damping"]["model"] = model;
  if (d.model == DampingProfile::ConstantCoefficient) {
    n["damping"]["coefficient"] = d.coefficient;
  } else {
    n["damping"]["ratio"] = d.ratio;
  }
  writeKeys(kDampingKeys, d, n["damping"]);
  n["simulation"]["integrator"] = toString(c.simulation.integrator);
  n["simulation"]["dynamics"] = toString(c.simulation.dynamics);
  writeKeys(kSimulationKeys, c.simulation, n["simulation"]);
  if (c.ste.active()) {
    writeKeys(kSteKeys, c.ste, n["ste"]);
    n["ste"]["damping"] = steDampingName(c.ste.damping);
  }
  return n;
}

}  // namespace gear_sim

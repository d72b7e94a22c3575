#include "gear_sim/config_yaml.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

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
bool keyName(const YAML::Node& key, const std::string& where, std::string* name,
             std::string* error) {
  if (key.IsScalar()) {
    *name = key.Scalar();
    return true;
  }
  if (error->empty())
    *error = where + quoted(key) + ": a key must be a plain name, not a sequence or mapping";
  return false;
}

// Reads one section: checks its keys against the known list and converts values, recording
// the first error with the full key name.
class Section {
 public:
  // (Copy-constructed: assigning a missing child to an existing YAML::Node throws.)
  Section(const YAML::Node& root, const std::string& name, std::string* error)
      : name_(name), error_(error), node_(root[name]) {
    if (node_ && !node_.IsMap()) fail(name_, "must be a mapping of keys");
  }
  bool present() const { return node_ && node_.IsMap(); }

  // Every key of the section must be in `known`.
  void allow(std::initializer_list<const char*> known) {
    if (!present() || !ok()) return;
    std::set<std::string> k(known.begin(), known.end());
    for (const auto& kv : node_) {
      std::string key;
      if (!keyName(kv.first, name_ + ".", &key, error_)) return;
      if (!k.count(key)) {
        std::string list;
        for (const char* s : known) list += std::string(list.empty() ? "" : ", ") + s;
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
    if (ok()) *error_ = key + ": " + what;
  }
  bool ok() const { return error_->empty(); }

 private:
  template <class T>
  static const char* typeName() {
    if constexpr (std::is_same_v<T, double>) return "a number";
    if constexpr (std::is_integral_v<T>) return "an integer";
    if constexpr (std::is_same_v<T, std::string>) return "a string";
    return "a list of numbers";
  }
  std::string name_;
  std::string* error_;
  const YAML::Node node_;
};

void readGear(Section& s, Gear* g) {
  s.allow({"teeth", "inertia", "base_radius"});
  s.get("teeth", &g->teeth);
  s.get("inertia", &g->inertia);
  s.get("base_radius", &g->base_radius);
}

void readMesh(Section& s, MeshOptions* m) {
  s.allow({"stiffness_model", "k_max", "k_min", "contact_ratio", "transition_fraction", "k_mean",
           "fourier_cos", "fourier_sin", "initial_phase"});
  s.getEnum("stiffness_model", &m->model, "square, trapezoid, fourier, constant");
  s.get("k_max", &m->k_max);
  s.get("k_min", &m->k_min);
  s.get("contact_ratio", &m->contact_ratio);
  s.get("transition_fraction", &m->transition_fraction);
  s.get("k_mean", &m->k_mean);
  s.get("fourier_cos", &m->fourier_cos);
  s.get("fourier_sin", &m->fourier_sin);
  s.get("initial_phase", &m->initial_phase);
}

void readSpeed(Section& s, SpeedOptions* o) {
  s.allow({"profile", "pinion_rpm", "end_rpm", "ramp_time"});
  s.getEnum("profile", &o->profile, "constant, ramp");
  s.get("pinion_rpm", &o->pinion_rpm);
  o->end_rpm = o->pinion_rpm;
  s.get("end_rpm", &o->end_rpm);
  s.get("ramp_time", &o->ramp_time);
}

std::string dirOf(const std::string& path) {
  const size_t p = path.find_last_of('/');
  return p == std::string::npos ? "." : path.substr(0, p);
}

}  // namespace

static bool loadGearModelImpl(const YAML::Node& root, GearModel* out, std::string* error) {
  std::string err;
  if (!root || !root.IsMap()) err = "the parameter file must be a YAML mapping of sections";
  for (const char* sec : {"pinion", "gear", "mesh", "speed"})
    if (err.empty() && !root[sec])
      err = std::string(sec) + ": missing section (pinion, gear, mesh and speed are required)";
  GearModel m;
  if (err.empty()) {
    Section p(root, "pinion", &err), g(root, "gear", &err), me(root, "mesh", &err),
        sp(root, "speed", &err);
    readGear(p, &m.gears.pinion);
    readGear(g, &m.gears.gear);
    readMesh(me, &m.mesh);
    readSpeed(sp, &m.speed);
  }
  if (err.empty()) err = m.validate();
  if (!err.empty()) {
    if (error) *error = err;
    return false;
  }
  *out = m;
  return true;
}

static bool loadSimConfigImpl(const YAML::Node& root, SimConfig* out, std::string* error,
                              const std::string& base_dir) {
  std::string err;
  SimConfig c;
  if (!root || !root.IsMap()) err = "the configuration must be a YAML mapping of sections";
  if (err.empty()) {
    // `encoder` is read by loadEncoderOptions (encoder_yaml.hpp).
    const std::set<std::string> sections{"pinion",  "gear",       "mesh", "speed",  "load",
                                         "damping", "simulation", "ste",  "encoder"};
    for (const auto& kv : root) {
      std::string key;
      if (!keyName(kv.first, "", &key, &err)) break;
      if (!sections.count(key)) {
        err = keyForMessage(key) +
              ": unknown section (known: pinion, gear, mesh, speed, load, damping, simulation, "
              "ste, encoder)";
        break;
      }
    }
  }
  if (err.empty()) {
    Section p(root, "pinion", &err), g(root, "gear", &err), me(root, "mesh", &err),
        sp(root, "speed", &err);
    readGear(p, &c.gears.pinion);
    readGear(g, &c.gears.gear);
    readMesh(me, &c.mesh);
    readSpeed(sp, &c.speed);

    Section l(root, "load", &err);
    l.allow({"profile", "mean", "amplitude", "frequency", "phase", "initial", "final", "step_time",
             "ramp_start", "ramp_end", "low", "high", "period", "rise", "hold", "fall", "times",
             "values", "file"});
    std::string profile = "sine";
    l.get("profile", &profile);
    if (profile == "csv") {
      // A CSV file with columns time [s] and torque [N*m] becomes a piecewise-linear table.
      std::string file;
      l.get("file", &file);
      if (err.empty() && file.empty()) l.fail("load.file", "required with load.profile = csv");
      if (err.empty()) {
        const std::string path = (!file.empty() && file[0] == '/') ? file : base_dir + "/" + file;
        SignalTable t;
        std::string e;
        if (!readTorqueCsv(path, &t, &e)) {
          // The path comes from the file: quoted in the message (the reader's starts with it).
          if (e.compare(0, path.size(), path) == 0)
            e = quoteForMessage(path) + e.substr(path.size());
          l.fail("load.file", e);
        } else {
          c.load.profile = LoadProfile::Table;
          c.load.times.assign(t.time.data(), t.time.data() + t.time.size());
          c.load.values.assign(t.torque.data(), t.torque.data() + t.torque.size());
        }
      }
    } else if (err.empty() && !parse(profile, &c.load.profile)) {
      l.fail("load.profile", "unknown name " + quoteForMessage(profile) +
                                 " (one of: constant, sine, step, ramp, trapezoid, table, csv)");
    }
    l.get("mean", &c.load.mean);
    l.get("amplitude", &c.load.amplitude);
    l.get("frequency", &c.load.frequency);
    l.get("phase", &c.load.phase);
    l.get("initial", &c.load.initial);
    l.get("final", &c.load.final_value);
    l.get("step_time", &c.load.step_time);
    l.get("ramp_start", &c.load.ramp_start);
    l.get("ramp_end", &c.load.ramp_end);
    l.get("low", &c.load.low);
    l.get("high", &c.load.high);
    l.get("period", &c.load.period);
    l.get("rise", &c.load.rise);
    l.get("hold", &c.load.hold);
    l.get("fall", &c.load.fall);
    if (profile != "csv") {
      l.get("times", &c.load.times);
      l.get("values", &c.load.values);
    }

    Section d(root, "damping", &err);
    d.allow({"model", "ratio", "coefficient", "load_sensitivity", "times", "ratios", "c0", "c1"});
    std::string model = "load_dependent";
    d.get("model", &model);
    if (model == "constant") {
      if (d.has("ratio") && d.has("coefficient"))
        d.fail("damping.coefficient", "give either damping.ratio or damping.coefficient, not both");
      c.damping.model = d.has("coefficient") ? DampingProfile::ConstantCoefficient
                                             : DampingProfile::ConstantRatio;
    } else if (model == "piecewise") {
      c.damping.model = DampingProfile::Piecewise;
    } else if (model == "load_dependent") {
      c.damping.model = DampingProfile::LoadDependent;
    } else if (model == "load_linear") {
      c.damping.model = DampingProfile::LoadLinear;
    } else {
      d.fail("damping.model", "unknown name " + quoteForMessage(model) +
                                  " (one of: constant, piecewise, load_dependent, load_linear)");
    }
    d.get("ratio", &c.damping.ratio);
    d.get("coefficient", &c.damping.coefficient);
    d.get("load_sensitivity", &c.damping.load_sensitivity);
    d.get("times", &c.damping.times);
    d.get("ratios", &c.damping.ratios);
    d.get("c0", &c.damping.c0);
    d.get("c1", &c.damping.c1);

    Section s(root, "simulation", &err);
    s.allow({"duration", "sample_rate", "integrator", "substeps", "dynamics", "initial_dte",
             "initial_velocity", "noise_snr_db", "seed"});
    s.get("duration", &c.simulation.duration);
    s.get("sample_rate", &c.simulation.sample_rate);
    s.getEnum("integrator", &c.simulation.integrator, "rk2, rk4");
    s.get("substeps", &c.simulation.substeps);
    s.getEnum("dynamics", &c.simulation.dynamics, "reduced, torsional");
    s.get("initial_dte", &c.simulation.initial_dte);
    s.get("initial_velocity", &c.simulation.initial_velocity);
    s.get("noise_snr_db", &c.simulation.noise_snr_db);
    s.get("seed", &c.simulation.seed);

    // Static transmission error (docs/ste.md): absent = none.
    Section st(root, "ste", &err);
    st.allow({"offset", "mesh_cos", "mesh_sin", "pinion_cos", "pinion_sin", "gear_cos", "gear_sin",
              "damping"});
    st.get("offset", &c.ste.offset);
    st.get("mesh_cos", &c.ste.mesh_cos);
    st.get("mesh_sin", &c.ste.mesh_sin);
    st.get("pinion_cos", &c.ste.pinion_cos);
    st.get("pinion_sin", &c.ste.pinion_sin);
    st.get("gear_cos", &c.ste.gear_cos);
    st.get("gear_sin", &c.ste.gear_sin);
    std::string ste_damping = "relative";
    st.get("damping", &ste_damping);
    if (ste_damping == "relative") {
      c.ste.damping = SteDamping::Relative;
    } else if (ste_damping == "dte") {
      c.ste.damping = SteDamping::Dte;
    } else {
      st.fail("ste.damping",
              "unknown name " + quoteForMessage(ste_damping) + " (one of: relative, dte)");
    }
  }
  if (err.empty()) err = c.validate();
  if (!err.empty()) {
    if (error) *error = err;
    return false;
  }
  *out = c;
  return true;
}

// yaml-cpp throws on some malformed documents the checks above do not foresee (a conversion of
// an unusual node): every such exception becomes an error, never an abort.
bool loadGearModel(const YAML::Node& root, GearModel* out, std::string* error) {
  try {
    return loadGearModelImpl(root, out, error);
  } catch (const YAML::Exception& e) {
    if (error) *error = "malformed YAML: " + quoteForMessage(e.what());
    return false;
  }
}

bool loadSimConfig(const YAML::Node& root, SimConfig* out, std::string* error,
                   const std::string& base_dir) {
  try {
    return loadSimConfigImpl(root, out, error, base_dir);
  } catch (const YAML::Exception& e) {
    if (error) *error = "malformed YAML: " + quoteForMessage(e.what());
    return false;
  }
}

namespace {
bool loadFile(const std::string& path, YAML::Node* root, std::string* error) {
  std::ifstream f(path);
  if (!f) {
    if (error) *error = path + ": cannot open";
    return false;
  }
  try {
    *root = YAML::Load(f);
  } catch (const YAML::Exception& e) {
    if (error)
      *error = path + ": YAML syntax error at line " + std::to_string(e.mark.line + 1) + ": " +
               quoteForMessage(e.msg);
    return false;
  }
  return true;
}
}  // namespace

bool loadSimConfigFile(const std::string& path, SimConfig* out, std::string* error) {
  YAML::Node root;
  if (!loadFile(path, &root, error)) return false;
  std::string e;
  if (!loadSimConfig(root, out, &e, dirOf(path))) {
    if (error) *error = path + ": " + e;
    return false;
  }
  return true;
}

bool loadGearModelFile(const std::string& path, GearModel* out, std::string* error) {
  YAML::Node root;
  if (!loadFile(path, &root, error)) return false;
  std::string e;
  if (!loadGearModel(root, out, &e)) {
    if (error) *error = path + ": " + e;
    return false;
  }
  return true;
}

YAML::Node toYaml(const SimConfig& c) {
  YAML::Node n;
  for (auto [name, g] : {std::pair{"pinion", &c.gears.pinion}, std::pair{"gear", &c.gears.gear}}) {
    n[name]["teeth"] = g->teeth;
    n[name]["inertia"] = g->inertia;
    n[name]["base_radius"] = g->base_radius;
  }
  auto& m = c.mesh;
  n["mesh"]["stiffness_model"] = toString(m.model);
  n["mesh"]["k_max"] = m.k_max;
  n["mesh"]["k_min"] = m.k_min;
  n["mesh"]["contact_ratio"] = m.contact_ratio;
  n["mesh"]["transition_fraction"] = m.transition_fraction;
  n["mesh"]["k_mean"] = m.k_mean;
  n["mesh"]["fourier_cos"] = m.fourier_cos;
  n["mesh"]["fourier_sin"] = m.fourier_sin;
  n["mesh"]["initial_phase"] = m.initial_phase;
  n["speed"]["profile"] = toString(c.speed.profile);
  n["speed"]["pinion_rpm"] = c.speed.pinion_rpm;
  n["speed"]["end_rpm"] = c.speed.end_rpm;
  n["speed"]["ramp_time"] = c.speed.ramp_time;
  auto& l = c.load;
  n["load"]["profile"] = toString(l.profile);
  for (auto [k, v] : {std::pair{"mean", l.mean},
                      {"amplitude", l.amplitude},
                      {"frequency", l.frequency},
                      {"phase", l.phase},
                      {"initial", l.initial},
                      {"final", l.final_value},
                      {"step_time", l.step_time},
                      {"ramp_start", l.ramp_start},
                      {"ramp_end", l.ramp_end},
                      {"low", l.low},
                      {"high", l.high},
                      {"period", l.period},
                      {"rise", l.rise},
                      {"hold", l.hold},
                      {"fall", l.fall}})
    n["load"][k] = v;
  n["load"]["times"] = l.times;
  n["load"]["values"] = l.values;
  auto& d = c.damping;
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
  n["damping"]["load_sensitivity"] = d.load_sensitivity;
  n["damping"]["times"] = d.times;
  n["damping"]["ratios"] = d.ratios;
  n["damping"]["c0"] = d.c0;
  n["damping"]["c1"] = d.c1;
  auto& s = c.simulation;
  n["simulation"]["duration"] = s.duration;
  n["simulation"]["sample_rate"] = s.sample_rate;
  n["simulation"]["integrator"] = toString(s.integrator);
  n["simulation"]["substeps"] = s.substeps;
  n["simulation"]["dynamics"] = toString(s.dynamics);
  n["simulation"]["initial_dte"] = s.initial_dte;
  n["simulation"]["initial_velocity"] = s.initial_velocity;
  n["simulation"]["noise_snr_db"] = s.noise_snr_db;
  n["simulation"]["seed"] = s.seed;
  if (c.ste.active()) {
    auto& e = c.ste;
    n["ste"]["offset"] = e.offset;
    n["ste"]["mesh_cos"] = e.mesh_cos;
    n["ste"]["mesh_sin"] = e.mesh_sin;
    n["ste"]["pinion_cos"] = e.pinion_cos;
    n["ste"]["pinion_sin"] = e.pinion_sin;
    n["ste"]["gear_cos"] = e.gear_cos;
    n["ste"]["gear_sin"] = e.gear_sin;
    n["ste"]["damping"] = e.damping == SteDamping::Relative ? "relative" : "dte";
  }
  return n;
}

}  // namespace gear_sim

// Sustained live streaming into damping_id_node and wavelet_node (issue 15): the tester is the
// rig. It simulates a short record (config/table1.yaml, ~record_seconds) and publishes it over
// and over with continuous indices (sample g = record[g mod N]) at ~rate samples/s in chunks of
// ~chunk_size for ~duration seconds of wall time, then checks:
// - nothing lost: both nodes received every sample sent and report 0 samples lost;
// - bounded memory: each node's resident memory (from its diagnostics) grows by at most
//   ~rss_growth_limit_mib between ~warmup seconds and the end;
// - every damping segment equals the offline identify() of the same samples: a record of two
//   copies gives each segment of the first copy exactly the samples and stencil context that
//   segment k (k mod M) of the endless stream sees;
// - with ~kill_after > 0: damping_id_node is killed (SIGKILL) at that time; launched with
//   respawn, it comes back and every complete segment after its return equals the offline one.
// It prints samples sent/received, losses, RSS at the start and the end and the growth per
// hour, per-segment latency p50/p99 (chunk completing the segment published -> its
// /gear/damping_segment received), and the estimates' drift against the truth. scripts/soak.sh
// runs it for minutes or hours. Nothing asserts a duration.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/callback_queue.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "../unit/support/status_support.hpp"
#include "gear_damping/DampingArray.h"
#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping_id/integral_method.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"

namespace gd = gear_damping_id;

namespace {

// Live and offline run the same core on the same samples; they differ only in how t0/dt are
// formed (index / fs vs the time column), a rounding-level difference.
constexpr double kLiveVsOfflineRelTol = 1e-9;
// The last segment of the stream and the first after a respawn lack stencil context on one
// side (see pipeline_tester.cpp, kGapBorderRelTol).
constexpr double kBorderRelTol = 1e-6;

// The subscriber callbacks run on their own thread (so that receipt times are not quantised by
// the publishing loop) and hold this mutex; so does every access from the test's thread.
std::mutex g_mu;

bool waitFor(const std::function<bool()>& pred, double timeout) {
  auto locked = [&] {
    std::lock_guard<std::mutex> lock(g_mu);
    return pred();
  };
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout);
  while (ros::ok() && !locked() && ros::WallTime::now() < deadline) {
    ros::WallDuration(0.01).sleep();
  }
  return locked();
}

// CPU time [s] (user + system) of process `pid` so far, NaN if unreadable.
double cpuSeconds(long pid) {
  std::FILE* f = std::fopen(("/proc/" + std::to_string(pid) + "/stat").c_str(), "r");
  if (f == nullptr) return std::nan("");
  char buf[4096];
  const size_t len = std::fread(buf, 1, sizeof(buf) - 1, f);
  std::fclose(f);
  buf[len] = 0;
  const char* p = std::strrchr(buf, ')');  // after the command name: fields 3..
  if (p == nullptr) return std::nan("");
  unsigned long utime = 0, stime = 0;
  // fields 14 and 15 (utime, stime) are the 12th and 13th after the state (field 3)
  if (std::sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %lu %lu", &utime, &stime) !=
      2) {
    return std::nan("");
  }
  return static_cast<double>(utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

struct NodeDiag {  // one node's stream diagnostics over time
  std::map<std::string, double> latest;
  double rss_start = std::nan(""), rss_warm = std::nan(""), rss_end = std::nan("");
  double t_warm = 0, t_end = 0;  // [s] since the stream started
  double cpu_warm = std::nan(""), cpu_end = std::nan(""), samples_warm = 0, samples_end = 0;
  double t_active_end = 0;  // [s] last report with new samples
  double value(const std::string& key) const {
    auto it = latest.find(key);
    return it == latest.end() ? std::nan("") : it->second;
  }
};

struct Segment {
  double C = 0, samples = 0, received = 0;  // received: wall time [s] since the stream start
};

TEST(LiveStream, SustainedRateLosesNothingStaysBoundedAndMatchesOffline) {
  ros::NodeHandle nh, pnh("~");
  ros::CallbackQueue queue;
  ros::NodeHandle cb_nh;
  cb_nh.setCallbackQueue(&queue);
  ros::AsyncSpinner spinner(1, &queue);
  double rate = 1e6, duration = 30.0, record_seconds = 0.1, warmup = 10.0, rss_limit = 8.0;
  double kill_after = 0.0, noise_snr_db = INFINITY;
  bool compare_offline = true;  // false for runs with refinement (auto on noisy data)
  int chunk_size = 1000;
  pnh.param("rate", rate, rate);
  pnh.param("duration", duration, duration);
  pnh.param("record_seconds", record_seconds, record_seconds);
  pnh.param("chunk_size", chunk_size, chunk_size);
  pnh.param("warmup", warmup, warmup);
  pnh.param("rss_growth_limit_mib", rss_limit, rss_limit);
  pnh.param("kill_after", kill_after, kill_after);
  pnh.param("noise_snr_db", noise_snr_db, noise_snr_db);
  pnh.param("compare_offline", compare_offline, compare_offline);

  // The record: table1.yaml, record_seconds long, a whole number of chunks and segments.
  gear_sim::SimConfig cfg;
  std::string e;
  ASSERT_TRUE(
      gear_test::ok(gear_sim::loadSimConfigFile(
                        ros::package::getPath("gear_damping") + "/config/table1.yaml", &cfg),
                    &e))
      << e;
  cfg.simulation.duration = record_seconds;
  cfg.simulation.noise_snr_db = noise_snr_db > 0.0 ? noise_snr_db : INFINITY;  // 0: none
  gear_sim::SignalTable rec;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &rec), &e)) << e;
  const double fs = cfg.simulation.sample_rate;
  const double seg_len = 1e-3;  // the node's default segment_length
  const Eigen::Index seg_samples = static_cast<Eigen::Index>(std::llround(seg_len * fs));
  const Eigen::Index n_chunks = rec.size() / chunk_size;
  const Eigen::Index n = n_chunks * chunk_size;
  ASSERT_GT(n_chunks, 1);
  ASSERT_EQ(n % seg_samples, 0) << "the record must hold whole segments";
  ASSERT_EQ(seg_samples % chunk_size == 0 || chunk_size % seg_samples == 0, true);
  const size_t m_segments = static_cast<size_t>(n / seg_samples);

  // Offline: identify() on two copies of the record, with the window the node resolves from
  // its first segment.
  gear_sim::SignalTable two;
  auto twice = [&](const Eigen::VectorXd& v, Eigen::VectorXd* out) {
    if (v.size() == 0) return;
    out->resize(2 * n);
    out->head(n) = v.head(n);
    out->tail(n) = v.head(n);
  };
  two.time.resize(2 * n);
  for (Eigen::Index i = 0; i < 2 * n; ++i) two.time[i] = static_cast<double>(i) / fs;
  twice(rec.dte, &two.dte);
  twice(rec.stiffness, &two.stiffness);
  twice(rec.torque, &two.torque);
  twice(rec.mesh_state, &two.mesh_state);
  twice(rec.mesh_phase, &two.mesh_phase);
  const gd::GearConstants gear = gd::gearConstants(cfg.gearModel());
  gd::IdentificationOptions o;
  o.refine = gd::IdentificationOptions::Refine::Never;  // as the .test files set
  gd::SignalView first = gd::SignalView::of(two);
  first.n = seg_samples;
  o.window_length = gd::defaultWindowLength(first, gear);
  gd::IdentificationResult offline;
  ASSERT_TRUE(gear_test::ok(gd::identify(two, gear, o, &offline), &e)) << e;
  ASSERT_GE(offline.segments.size(), m_segments);
  std::vector<double> truth(m_segments);  // segment-mean true C [1/s]
  for (size_t i = 0; i < m_segments; ++i) {
    truth[i] = rec.damping.segment(static_cast<Eigen::Index>(i) * seg_samples, seg_samples).mean() /
               gear.equivalent_mass;
  }

  // Chunks: precomputed, only first_index and the stamp change per publication.
  std::vector<gear_damping::SignalChunk> chunks(static_cast<size_t>(n_chunks));
  for (Eigen::Index k = 0; k < n_chunks; ++k) {
    auto& c = chunks[static_cast<size_t>(k)];
    gear_sim_ros::toChunk(rec, k * chunk_size, chunk_size, fs, 0, &c);
    c.dte_velocity.clear();  // simulation-only channels the nodes do not use
    c.damping.clear();
  }

  // Collectors.
  std::map<long, Segment> segments;      // by segment number
  std::vector<double> latency;           // [s]
  std::vector<double> published;         // wall time [s] each chunk was published, since start
  std::map<std::string, NodeDiag> diag;  // "damping_id", "wavelet"
  ros::WallTime start;
  bool started = false;
  auto since = [&] { return started ? (ros::WallTime::now() - start).toSec() : 0.0; };
  ros::Subscriber seg_sub = cb_nh.subscribe<gear_damping::DampingArray>(
      "/gear/damping_segment", 100000,
      boost::function<void(const gear_damping::DampingArray::ConstPtr&)>(
          [&](const gear_damping::DampingArray::ConstPtr& m) {
            std::lock_guard<std::mutex> lock(g_mu);
            if (m->segments.size() != 1) return;
            const auto& s = m->segments[0];
            const long k = std::lround(s.t_start / seg_len);
            Segment& x = segments[k];
            x.C = s.C;
            x.samples = std::round((s.t_end - s.t_start) * fs);
            x.received = since();
            // The segment completes with the chunk holding its last sample + 2 (stencil context).
            const size_t completing = static_cast<size_t>(((k + 1) * seg_samples + 2) / chunk_size);
            if (completing < published.size())
              latency.push_back(x.received - published[completing]);
          }),
      ros::VoidConstPtr(), ros::TransportHints().tcpNoDelay());
  ros::Subscriber diag_sub = cb_nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 1000, [&](const diagnostic_msgs::DiagnosticArray::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(g_mu);
        for (const auto& st : m->status) {
          const std::string node = st.name.rfind("damping_id:", 0) == 0 ? "damping_id"
                                   : st.name.rfind("wavelet:", 0) == 0  ? "wavelet"
                                                                        : "";
          if (node.empty()) continue;
          NodeDiag& d = diag[node];
          for (const auto& kv : st.values) d.latest[kv.key] = std::atof(kv.value.c_str());
          if (st.name.find(": stream") == std::string::npos) continue;
          const double rss = d.value("resident memory [MiB]");
          if (!started) continue;
          if (std::isnan(d.rss_start)) d.rss_start = rss;
          const long pid = std::lround(d.value("process id"));
          const double samples = d.value("samples in chunks received");
          if (std::isnan(d.rss_warm) && since() >= warmup) {
            d.rss_warm = rss, d.t_warm = since();
            d.cpu_warm = cpuSeconds(pid), d.samples_warm = samples;
          }
          d.rss_end = rss;
          d.t_end = since();
          if (samples > d.samples_end) {
            d.cpu_end = cpuSeconds(pid), d.samples_end = samples, d.t_active_end = since();
          }
        }
      });
  spinner.start();
  ros::Publisher params = nh.advertise<gear_damping::GearParams>("/gear/params", 1, true);
  params.publish(gear_sim_ros::toMsg(cfg.gearModel()));
  ros::Publisher signal = nh.advertise<gear_damping::SignalChunk>("/gear/signal", 10000);
  ASSERT_TRUE(waitFor([&] { return signal.getNumSubscribers() >= 2; }, 60.0))
      << "damping_id_node and wavelet_node must subscribe";
  ASSERT_TRUE(waitFor([&] { return diag.count("damping_id") && diag.count("wavelet"); }, 30.0));
  ros::WallDuration(1.0).sleep();  // the latched parameters

  // Publish at the rate (absolute deadlines: a late chunk is sent at once, catching up).
  const double period = static_cast<double>(chunk_size) / rate;
  const unsigned long total = static_cast<unsigned long>(duration / period);
  published.reserve(total);
  {
    std::lock_guard<std::mutex> lock(g_mu);
    start = ros::WallTime::now();
    started = true;
  }
  long pid_killed = 0;
  double killed_at = -1.0;
  for (unsigned long i = 0; i < total && ros::ok(); ++i) {
    const double due = static_cast<double>(i) * period;
    const double wait = due - since();
    if (wait > 0) ros::WallDuration(wait).sleep();
    auto& c = chunks[i % static_cast<size_t>(n_chunks)];
    c.first_index = static_cast<std::uint64_t>(i) * static_cast<std::uint64_t>(chunk_size);
    c.header.stamp = ros::Time::now();
    {
      std::lock_guard<std::mutex> lock(g_mu);
      published.push_back(since());
    }
    signal.publish(c);
    if (kill_after > 0 && pid_killed == 0 && since() >= kill_after) {
      {
        std::lock_guard<std::mutex> lock(g_mu);
        pid_killed = std::lround(diag["damping_id"].value("process id"));
      }
      ASSERT_GT(pid_killed, 1);
      ASSERT_EQ(::kill(static_cast<pid_t>(pid_killed), SIGKILL), 0);
      killed_at = since();
      std::printf("[live] killed damping_id_node (pid %ld) at %.2f s\n", pid_killed, killed_at);
    }
  }
  const double sent_for = since();
  const unsigned long sent = total * static_cast<unsigned long>(chunk_size);
  const long last_segment = static_cast<long>(sent / static_cast<unsigned long>(seg_samples)) - 1;
  // Both nodes drain their queues; the last segment is flushed at the end of the stream.
  const bool drained = waitFor(
      [&] {
        return kill_after <= 0 &&
               diag["damping_id"].value("samples in chunks received") >=
                   static_cast<double>(sent) &&
               diag["wavelet"].value("samples in chunks received") >= static_cast<double>(sent) &&
               segments.count(last_segment);
      },
      kill_after > 0 ? 10.0 : 120.0);
  waitFor([] { return false; }, 3.0);   // final diagnostics (period 1 s)
  if (kill_after <= 0) spinner.stop();  // the respawn check below still needs diagnostics
  std::unique_lock<std::mutex> report_lock(g_mu, std::defer_lock);
  if (kill_after > 0) report_lock.lock();

  // Report.
  const NodeDiag& di = diag["damping_id"];
  const NodeDiag& wv = diag["wavelet"];
  std::printf(
      "[live] %.3g samples/s in chunks of %d for %.1f s (%.1f s to send): %lu samples sent\n", rate,
      chunk_size, duration, sent_for, sent);
  for (const auto* d : {&di, &wv}) {
    const char* name = d == &di ? "damping_id" : "wavelet";
    const double hours = (d->t_end - d->t_warm) / 3600.0;
    std::printf(
        "[live] %s: received %.0f samples; lost %.0f (never arrived %.0f, rejected %.0f, late "
        "%.0f);"
        " gaps %.0f, duplicate %.0f, rejected chunks %.0f; RSS start %.1f MiB, after warm-up (%.0f "
        "s) "
        "%.1f MiB, end %.1f MiB: growth after warm-up %.2f MiB/h\n",
        name, d->value("samples received"), d->value("samples lost"),
        d->value("samples lost: never arrived (queue overflow, transport)"),
        d->value("samples lost: rejected"), d->value("samples lost: late"), d->value("gaps"),
        d->value("samples duplicate"), d->value("dropped chunks"), d->rss_start, d->t_warm,
        d->rss_warm, d->rss_end, hours > 0 ? (d->rss_end - d->rss_warm) / hours : std::nan(""));
    const double cpu = d->cpu_end - d->cpu_warm;
    std::printf(
        "[live] %s: %.3g CPU s for %.3g samples after warm-up: capacity %.3g samples/s at "
        "100 %% of one core (%.0f %% of a core at this rate)\n",
        name, cpu, d->samples_end - d->samples_warm, (d->samples_end - d->samples_warm) / cpu,
        100.0 * cpu / std::max(d->t_active_end - d->t_warm, 1e-9));
  }
  std::printf(
      "[live] segments received %zu of %ld; latency p50 %.3g ms, p99 %.3g ms, max %.3g ms\n",
      segments.size(), last_segment + 1, 1e3 * percentile(latency, 0.5),
      1e3 * percentile(latency, 0.99), 1e3 * percentile(latency, 1.0));
  // Drift against the truth: mean relative error of the first and the last tenth of the segments.
  std::vector<double> errs;
  for (const auto& [k, s] : segments) {
    const double t = truth[static_cast<size_t>(k) % m_segments];
    errs.push_back(std::abs(s.C - t) / t);
  }
  if (errs.size() >= 20) {
    const size_t tenth = errs.size() / 10;
    double a = 0, b = 0;
    for (size_t i = 0; i < tenth; ++i) a += errs[i], b += errs[errs.size() - 1 - i];
    std::printf(
        "[live] |C - truth| / truth: first tenth mean %.4g, last tenth mean %.4g (drift %.3g)\n",
        a / static_cast<double>(tenth), b / static_cast<double>(tenth),
        (b - a) / static_cast<double>(tenth));
  }
  std::printf(
      "[live] damping_id: refinement degraded %.0f, refinement load %.3g, segments with "
      "refinement skipped %.0f; wavelet: windows analysed %.0f, skipped for load %.0f, "
      "analysis load %.3g (CPU s per s of stream while analysing)\n",
      di.value("refinement degraded"), di.value("refinement load [core fraction]"),
      di.value("segments with refinement skipped"), wv.value("windows analysed"),
      wv.value("windows skipped (load)"), wv.value("analysis load [core fraction]"));

  // Checks.
  double worst = 0.0;
  long after_kill = 0;
  for (const auto& [k, s] : segments) {
    const auto& off = offline.segments[static_cast<size_t>(k) % m_segments];
    const bool border =
        k == last_segment || (killed_at >= 0 && s.received > killed_at && after_kill++ == 0);
    if (s.samples != static_cast<double>(seg_samples)) {
      EXPECT_TRUE(killed_at >= 0) << "partial segment " << k << " without a gap or a kill";
      continue;  // the piece of a segment cut by the respawn
    }
    if (!compare_offline) continue;
    const double rel = std::abs(s.C - off.C) / off.C;
    worst = std::max(worst, border ? 0.0 : rel);
    EXPECT_LE(rel, border ? kBorderRelTol : kLiveVsOfflineRelTol) << "segment " << k;
  }
  std::printf("[live] live vs offline identify(): max rel diff %.3g\n", worst);
  if (kill_after > 0) {
    report_lock.unlock();
    // Respawned: the node reports a new pid, and it identified complete segments again.
    ASSERT_TRUE(waitFor(
        [&] {
          const double pid = diag["damping_id"].value("process id");
          return std::isfinite(pid) && std::lround(pid) != pid_killed;
        },
        30.0))
        << "damping_id_node was not respawned";
    std::lock_guard<std::mutex> lock(g_mu);
    long complete_after = 0;
    for (const auto& [k, s] : segments) {
      if (s.received > killed_at && s.samples == static_cast<double>(seg_samples)) ++complete_after;
    }
    EXPECT_GT(complete_after, 100) << "complete segments identified after the respawn";
    std::printf("[live] after the respawn: %ld complete segments, all equal to offline\n",
                complete_after);
    return;
  }
  EXPECT_TRUE(drained) << "the nodes did not receive every sample";
  EXPECT_EQ(segments.size(), static_cast<size_t>(last_segment + 1)) << "segments identified";
  for (const auto* d : {&di, &wv}) {
    const char* name = d == &di ? "damping_id" : "wavelet";
    EXPECT_EQ(d->value("samples received"), static_cast<double>(sent)) << name;
    EXPECT_EQ(d->value("samples lost"), 0.0) << name;
    EXPECT_EQ(d->value("samples rejected"), 0.0) << name;
    ASSERT_TRUE(std::isfinite(d->rss_warm) && std::isfinite(d->rss_end)) << name;
    EXPECT_LE(d->rss_end - d->rss_warm, rss_limit) << name << ": resident memory growth [MiB]";
  }
  EXPECT_GE(wv.value("windows analysed"), 1.0);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "live_stream_tester");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}

"""Figures and an HTML page from an analysis result directory (see docs/report.md).

RESULT_DIR holds signal.csv, result.json and tables/ as written by scripts/demo.sh and
`analyze --output RESULT_DIR/result.json --csv-out RESULT_DIR/tables`. Every figure is a
1200 x 750 px PNG; a figure whose inputs are missing is skipped with a note. Values that should
not be trusted as they are (not identifiable, C <= 0, xi >= 1, fit < 0, any warning, a wavelet
mode that is no free decay) are highlighted with the reason."""
import csv
import datetime
import hashlib
import html
import json
import math
import os
import sys
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

FIGSIZE, DPI = (8.0, 5.0), 150  # 1200 x 750 px

# (file, title) of every figure, in the order of the paper.
FIGURES = [
    ("fig04_load_stiffness.png", "Fig. 4: load torque and mesh stiffness"),
    ("fig05_dte.png", "Fig. 5: dynamic transmission error"),
    ("fig06_response_legacy.png", "Fig. 6: modeled vs observed DTE, legacy formulation"),
    ("fig07_response_constant.png", "Fig. 7: modeled vs observed DTE, constant damping"),
    ("fig08_damping.png", "Fig. 8: identified damping C(t)"),
    ("fig08b_stiffness_curve.png", "Identified stiffness curve over a mesh cycle (greybox shape)"),
    ("fig09_response_piecewise.png", "Fig. 9: modeled vs observed DTE, piecewise damping"),
    ("fig09b_response_load_law.png", "Modeled vs observed DTE, load-law damping"),
    ("fig10_scalogram.png", "Fig. 10: Morlet scalogram with the cone of influence"),
    ("fig11_spectrum.png", "Fig. 11: spectrum with the picked modes"),
    ("fig12_envelopes.png", "Fig. 12: wavelet envelopes and their decay fits"),
    ("fig13_ste.png", "Identified static transmission error (docs/ste.md)"),
]


class Missing(Exception):
    """An input a figure needs is absent."""


class NotApplicable(Exception):
    """The figure does not belong to this kind of result (e.g. no STE identified): omitted
    without a note."""


def read_csv(path):
    if not os.path.exists(path):
        raise Missing(os.path.basename(path) + " not found")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(row for row in f if not row.startswith("#")))
    if not rows:
        raise Missing(os.path.basename(path) + " is empty")
    return rows


def col(rows, name):
    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return math.nan
    return np.array([num(r.get(name)) for r in rows])


def fval(v):
    return math.nan if v is None else float(v)


def fnum(v):
    """A number from JSON or CSV text; NaN when absent or not a number."""
    try:
        return math.nan if v is None or v == "" else float(v)
    except (TypeError, ValueError):
        return math.nan


def new_fig(nrows=1, height_ratios=None):
    fig, axes = plt.subplots(nrows, 1, figsize=FIGSIZE, dpi=DPI, sharex=nrows > 1, squeeze=False,
                             gridspec_kw={"height_ratios": height_ratios} if height_ratios else None)
    return fig, [a[0] for a in axes]


def warnings_of(obj):
    """(code, text) of every warning of a segment, run or mode: `warnings` is a list of
    {code, text} (or of plain strings), `warning` a single text (older results)."""
    out = []
    for w in (obj or {}).get("warnings") or []:
        if isinstance(w, dict):
            out.append((str(w.get("code") or ""), str(w.get("text") or "")))
        else:
            out.append(("", str(w)))
    if (obj or {}).get("warning"):
        out.append(("", str(obj["warning"])))
    return out


def segment_flags(s):
    """Why a segment estimate should not be trusted as is (empty when clean)."""
    flags = []
    if s.get("identifiable") is False:
        flags.append(("not_identifiable", s.get("reason") or "not identifiable"))
    c, xi = s.get("C"), s.get("xi")
    if c is not None and c <= 0:
        flags.append(("nonpositive_damping", f"C = {c:.4g} 1/s <= 0"))
    if xi is not None and xi >= 1:
        flags.append(("overdamped", f"xi = {xi:.4g} >= 1"))
    return flags + warnings_of(s)


def run_flags(r):
    flags = []
    fit = fval((r.get("response") or {}).get("fit_percent"))
    if math.isfinite(fit) and fit < 0:
        flags.append(("negative_fit", f"fit {fit:.1f} % < 0: the modeled response is worse than "
                                      "the mean (diverged)"))
    const = r.get("constant")
    if const:
        flags += segment_flags(const)
    ll = r.get("load_law")
    if ll and ll.get("identifiable") is False:
        flags.append(("not_identifiable", "load law: " + (ll.get("reason") or "not identifiable")))
    return flags + warnings_of(r)


def mode_flags(m):
    flags = []
    if m.get("free_decay") is False:
        flags.append(("forced_line", "a forced line, not a free decay: its xi is not damping"))
    xi = m.get("damping_ratio")
    if xi is not None and (xi <= 0 or xi >= 1):
        flags.append(("implausible_ratio", f"xi = {xi:.4g} outside (0, 1)"))
    return flags + warnings_of(m)


def flags_html(flags):
    return "; ".join(html.escape(f"{c}: {t}" if c and t else (c or t)) for c, t in flags)


def flag_attr(flags):
    """class and title attributes of a cell or row holding flagged values."""
    if not flags:
        return ""
    return f" class='flag' title='{flags_html(flags)}'"


def free_decay_modes(modes):
    return [m for m in modes if m.get("free_decay") is not False]


class Progress:
    """A progress line on stderr while the figures are drawn, only on a terminal (not --quiet)."""

    def __init__(self, total, enabled):
        self.total, self.on, self.t0 = total, enabled and sys.stderr.isatty(), time.monotonic()
        self.width = 0

    def step(self, done, what):
        if not self.on:
            return
        f = min(1.0, done / max(1, self.total))
        line = (f"report [{'#' * int(24 * f)}{'.' * (24 - int(24 * f))}] {done}/{self.total}  "
                f"{time.monotonic() - self.t0:.1f} s  {what}")
        sys.stderr.write("\r" + line + " " * max(0, self.width - len(line)))
        sys.stderr.flush()
        self.width = max(self.width, len(line))

    def finish(self):
        if self.on and self.width:
            sys.stderr.write("\r" + " " * self.width + "\r")
            sys.stderr.flush()


def save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


class Report:
    def __init__(self, result_dir, out_dir):
        self.dir = result_dir
        self.out = out_dir
        self.tables = os.path.join(result_dir, "tables")
        with open(os.path.join(result_dir, "result.json")) as f:
            self.res = json.load(f)
        self.runs = {(r["formulation"], r["model"]): r for r in self.res.get("runs", [])}
        self._signal = None

    def signal(self):
        if self._signal is None:
            path = os.path.join(self.dir, "signal.csv")
            if not os.path.exists(path):
                raise Missing("signal.csv not found")
            self._signal = np.genfromtxt(path, delimiter=",", names=True)
        return self._signal

    def mode_is_forced(self, k):
        modes = self.res.get("wavelet", {}).get("modes", [])
        return k < len(modes) and modes[k].get("free_decay") is False

    def me(self):
        return fval(self.res.get("identification", {}).get("equivalent_mass"))

    # Fig. 4
    def fig04_load_stiffness(self, path):
        s = self.signal()
        names = s.dtype.names
        if "torque" not in names or "stiffness" not in names:
            raise Missing("signal.csv has no torque or stiffness column")
        fig, (a, b) = new_fig(2)
        a.plot(s["time"] * 1e3, s["torque"], lw=1)
        a.set_ylabel("pinion torque T1 [N·m]")
        b.plot(s["time"] * 1e3, s["stiffness"] / 1e8, lw=0.8)
        b.set_ylabel("mesh stiffness k [1e8 N/m]")
        b.set_xlabel("time [ms]")
        save(fig, path)

    # Fig. 5
    def fig05_dte(self, path):
        s = self.signal()
        fig, (a,) = new_fig()
        a.plot(s["time"] * 1e3, s["dte"] * 1e6, lw=0.6)
        a.set_xlabel("time [ms]")
        a.set_ylabel("DTE y [µm]")
        save(fig, path)

    def response(self, path, formulation, model, label):
        rows = read_csv(os.path.join(self.tables, f"response_{formulation}_{model}.csv"))
        run = self.runs.get((formulation, model), {})
        fit = fval(run.get("response", {}).get("fit_percent"))
        unmodeled = run.get("response", {}).get("unmodeled_samples") or 0
        t, y, yh = col(rows, "time"), col(rows, "observed"), col(rows, "modeled")
        fig, (a, r) = new_fig(2, height_ratios=[3, 1.3])
        a.plot(t * 1e3, y * 1e6, lw=1.2, label="observed")
        lim = np.nanmax(np.abs(y)) * 1e6
        diverged = np.nanmax(np.abs(yh)) * 1e6 > 3 * lim
        a.plot(t * 1e3, np.clip(yh * 1e6, -3 * lim, 3 * lim), "--", lw=1.0,
               label=f"modeled, {label} (fit {fit:.1f} %)" + (", clipped" if diverged else "")
               + (f", {unmodeled} samples not modeled" if unmodeled else ""))
        a.set_ylim(-1.5 * lim if np.nanmin(y) < 0 else 0, 1.5 * lim)
        a.set_ylabel("DTE y [µm]")
        a.legend(loc="upper right", fontsize=8)
        res = (y - yh) * 1e6
        rms = math.sqrt(np.nanmean(res ** 2)) if np.isfinite(res).any() else math.nan
        r.plot(t * 1e3, np.clip(res, -3 * lim, 3 * lim), lw=0.7, color="C3",
               label=f"residual y − ŷ (RMS {rms:.3g} µm)")
        r.axhline(0, color="0.5", lw=0.6)
        rl = min(3 * lim, 1.2 * np.nanmax(np.abs(res))) if np.isfinite(res).any() else lim
        r.set_ylim(-rl, rl)
        r.set_ylabel("residual [µm]")
        r.set_xlabel("time [ms]")
        r.legend(loc="upper right", fontsize=8)
        save(fig, path)

    def fig06_response_legacy(self, path):
        self.response(path, "legacy", "constant", "legacy formulation, constant damping")

    def fig07_response_constant(self, path):
        self.response(path, "known", "constant", "constant damping")

    def fig09_response_piecewise(self, path):
        self.response(path, "known", "piecewise", "piecewise damping")

    def fig09b_response_load_law(self, path):
        self.response(path, "known", "load_law", "load-law damping")

    # Fig. 8
    def fig08_damping(self, path):
        pw = self.runs.get(("known", "piecewise")) or self.res.get("identification")
        if not pw or not pw.get("segments"):
            raise Missing("no piecewise segments in result.json")
        me = self.me()
        fig, (a,) = new_fig()
        for s in pw["segments"]:
            if s.get("C") is None:
                continue
            tm = 0.5 * (s["t_start"] + s["t_end"]) * 1e3
            a.errorbar(tm, s["C"], yerr=2 * fval(s.get("C_std")), fmt="o", color="C0", capsize=4)
            a.hlines(s["C"], s["t_start"] * 1e3, s["t_end"] * 1e3, color="C0", lw=2)
        a.plot([], [], "o-", color="C0", label="piecewise C ± 2 SE")
        try:
            sig = self.signal()
            if "damping" in sig.dtype.names and math.isfinite(me):
                a.plot(sig["time"] * 1e3, sig["damping"] / me, color="k", lw=1, label="true c(t)/Me")
        except Missing:
            sig = None
        const = (self.runs.get(("known", "constant")) or {}).get("constant")
        if const and const.get("C") is not None:
            a.axhline(const["C"], color="C1", ls="--", label=f"constant C = {const['C']:.0f} 1/s")
        ll = (self.runs.get(("known", "load_law")) or {}).get("load_law")
        if ll and ll.get("c0") is not None and sig is not None and "torque" in sig.dtype.names:
            a.plot(sig["time"] * 1e3, (ll["c0"] + ll["c1"] * sig["torque"]) / me, color="C2", ls=":",
                   lw=2, label="load law (c0 + c1·T1)/Me")
        a.set_xlabel("time [ms]")
        a.set_ylabel("damping C = c/Me [1/s]")
        a.legend(loc="best")
        save(fig, path)

    def fig08b_stiffness_curve(self, path):
        """The greybox fourier:H / table:N stiffness curve of every segment against the mesh
        phase, beside the measured stiffness when signal.csv has it."""
        run = next((r for r in self.res.get("runs", [])
                    if r.get("stiffness_shape", "square") != "square"
                    and any(s.get("stiffness_curve") for s in r.get("segments", []))), None)
        if run is None:
            raise NotApplicable("no greybox fourier/table stiffness shape in result.json")
        kind, _, n = run["stiffness_shape"].partition(":")
        u = np.linspace(0.0, 1.0, 401)

        def curve(theta):
            theta = np.asarray([fval(v) for v in theta])
            if kind == "fourier":
                k = np.full_like(u, theta[0])
                for h in range(1, (len(theta) - 1) // 2 + 1):
                    k += theta[2 * h - 1] * np.cos(2 * np.pi * h * u)
                    k += theta[2 * h] * np.sin(2 * np.pi * h * u)
                return k
            nodes = np.arange(len(theta) + 1) / len(theta)  # periodic: node N = node 0
            return np.interp(u, nodes, np.append(theta, theta[0]))

        fig, (a,) = new_fig()
        try:
            s = self.signal()
            names = s.dtype.names or ()
            if "stiffness" in names and "mesh_phase" in names:
                step = max(1, len(s) // 20000)
                ph = np.mod(s["mesh_phase"][::step], 1.0)
                a.plot(ph, s["stiffness"][::step] / 1e8, ".", ms=1.5, color="0.7",
                       label="measured stiffness (signal.csv)")
        except Missing:
            pass
        segs = [x for x in run["segments"] if x.get("identifiable") and x.get("stiffness_curve")]
        cmap = plt.get_cmap("viridis")
        for i, seg in enumerate(segs):
            flagged = bool(segment_flags(seg))
            a.plot(u, curve(seg["stiffness_curve"]) / 1e8, lw=1.2, ls="--" if flagged else "-",
                   color=cmap(i / max(1, len(segs) - 1)),
                   label=(f"segment {fnum(seg.get('t_start')) * 1e3:.1f} ms"
                          + (" (flagged)" if flagged else "")) if i < 12 else None)
        a.set_xlabel("mesh phase [cycles]")
        a.set_ylabel("mesh stiffness k [1e8 N/m]")
        a.set_title(f"{run['formulation']} {run['stiffness_shape']}, {run.get('estimator', '')}",
                    fontsize=9)
        a.legend(loc="upper right", fontsize=7, framealpha=0.9)
        save(fig, path)

    # Fig. 10
    def fig10_scalogram(self, path):
        p = os.path.join(self.tables, "wavelet_scalogram.csv")
        if not os.path.exists(p):
            raise Missing("wavelet_scalogram.csv not found")
        m = np.loadtxt(p, delimiter=",", comments="#")
        times, freqs, coi, w = m[0, 2:], m[1:, 0], m[1:, 1], m[1:, 2:]
        peak = np.nanmax(w)
        if not (peak > 0):
            raise Missing("wavelet_scalogram.csv holds no non-zero coefficient")
        db = 20 * np.log10(np.maximum(w, peak * 1e-8) / peak)  # amplitude in dB re the peak
        fig, (a,) = new_fig()
        pc = a.pcolormesh(times * 1e3, freqs, db, shading="auto", cmap="magma", vmin=-80, vmax=0)
        fig.colorbar(pc, ax=a, label="|W| [dB re peak]")
        t0, t1 = times[0], times[-1]
        left = np.minimum(t0 + coi, t1)
        right = np.maximum(t1 - coi, t0)
        a.fill_betweenx(freqs, t0 * 1e3, left * 1e3, color="w", alpha=0.3, hatch="//", lw=0)
        a.fill_betweenx(freqs, right * 1e3, t1 * 1e3, color="w", alpha=0.3, hatch="//", lw=0)
        a.plot(left * 1e3, freqs, color="w", lw=1)
        a.plot(right * 1e3, freqs, color="w", lw=1, label="cone of influence (hatched: edge effects)")
        for k, mode in enumerate(self.res.get("wavelet", {}).get("modes", [])):
            f = fval(mode.get("frequency_hz"))
            if not math.isfinite(f):
                continue
            forced = mode.get("free_decay") is False
            a.axhline(f, color="c" if not forced else "0.7", ls="--" if not forced else ":", lw=1)
            text = (f"mode {k + 1}: {f:.0f} Hz, " +
                    ("forced line" if forced else f"ξ = {fval(mode.get('damping_ratio')):.4f}"))
            a.annotate(text, (1.0, f), xycoords=("axes fraction", "data"), xytext=(-4, 3),
                       textcoords="offset points", ha="right", va="bottom", color="w", fontsize=8)
        a.set_yscale("log")
        a.set_xlabel("time [ms]")
        a.set_ylabel("frequency [Hz]")
        a.legend(loc="lower left", fontsize=8, framealpha=0.6)
        save(fig, path)

    # Fig. 11
    def fig11_spectrum(self, path):
        rows = read_csv(os.path.join(self.tables, "wavelet_spectrum.csv"))
        kind = np.array([r["kind"] for r in rows])
        f, p = col(rows, "frequency_hz"), col(rows, "power")
        fig, (a,) = new_fig()

        def db(sel):  # power in dB re its own peak: both curves on one axis
            v = p[sel]
            return 10 * np.log10(np.maximum(v, np.nanmax(v) * 1e-12) / np.nanmax(v))

        psd = (kind == "psd") & (f > 0) & (p > 0)
        sc = (kind == "scalogram") & (f > 0) & (p > 0)
        if psd.any():
            a.semilogx(f[psd], db(psd), lw=0.6, color="0.55", label="PSD (FFT)")
        if sc.any():
            a.semilogx(f[sc], db(sc), color="C0", lw=1.6, label="time-averaged scalogram |W|²")
        for k, m in enumerate(self.res.get("wavelet", {}).get("modes", [])):
            fm = fval(m.get("frequency_hz"))
            if not math.isfinite(fm):
                continue
            forced = m.get("free_decay") is False
            a.axvline(fm, color="0.6" if forced else "C3", ls=":" if forced else "--", lw=1,
                      label=("picked modes" if k == 0 else None))
            a.annotate(f"{fm:.0f} Hz" + (" (forced)" if forced else ""), (fm, 1.0),
                       xycoords=("data", "axes fraction"), xytext=(3, -4), textcoords="offset points",
                       rotation=90, va="top", ha="left", color="0.4" if forced else "C3", fontsize=8)
        a.set_ylim(-80, 5)
        a.set_xlabel("frequency [Hz]")
        a.set_ylabel("power [dB re peak]")
        a.grid(True, which="both", alpha=0.3)
        a.legend(loc="lower left", fontsize=8, framealpha=0.9)
        save(fig, path)

    # Fig. 12
    def fig12_envelopes(self, path):
        env = read_csv(os.path.join(self.tables, "wavelet_envelopes.csv"))
        modes = read_csv(os.path.join(self.tables, "wavelet_modes.csv"))
        mode, t, e = col(env, "mode"), col(env, "time"), col(env, "envelope")
        fig, (a,) = new_fig()
        for k, m in enumerate(modes):
            sel = (mode == k) & (e > 0)
            if not sel.any():
                continue
            forced = self.mode_is_forced(k)
            a.semilogy(t[sel] * 1e3, e[sel] * 1e6, lw=1, color=f"C{k}",
                       label=f"{fnum(m.get('frequency_hz')):.0f} Hz: " +
                             ("forced line, not a free decay" if forced else
                              f"wavelet ξ = {fnum(m.get('damping_ratio')):.4f}, "
                              f"R² = {fnum(m.get('r2')):.3f}"))
            sigma, t0, t1 = fnum(m.get("sigma_per_s")), fnum(m.get("t_start_s")), fnum(m.get("t_end_s"))
            if all(math.isfinite(v) for v in (sigma, t0, t1)):
                reg = sel & (t >= t0) & (t <= t1)
                if reg.any():
                    a0 = np.mean(np.log(e[reg]) + sigma * t[reg])  # intercept for the known slope
                    tt = np.linspace(t0, t1, 50)
                    a.semilogy(tt * 1e3, np.exp(a0 - sigma * tt) * 1e6, "k--", lw=1.5)
                    a.axvspan(t0 * 1e3, t1 * 1e3, color=f"C{k}", alpha=0.08)
                    # The integral method's xi as a decay rate: sigma = xi wd / sqrt(1 - xi^2).
                    xi_i, fd = fnum(m.get("integral_damping_ratio")), fnum(m.get("frequency_hz"))
                    if math.isfinite(xi_i) and 0 < xi_i < 1 and math.isfinite(fd):
                        s_i = xi_i * 2 * math.pi * fd / math.sqrt(1 - xi_i ** 2)
                        a.semilogy(tt * 1e3, np.exp(a0 - sigma * t0 - s_i * (tt - t0)) * 1e6,
                                   ":", color=f"C{k}", lw=2.2,
                                   label=f"integral method: ξ = {xi_i:.4f}")
        a.plot([], [], "k--", label="wavelet fit ln|W| = a − σt (decay region shaded)")
        a.set_xlabel("time [ms]")
        a.set_ylabel("envelope |W(f_mode, t)| [µm]")
        a.legend(loc="upper right", fontsize=7, framealpha=0.9)
        save(fig, path)

    # The STE spectrum (analyze --ste, docs/ste.md)
    def fig13_ste(self, path):
        ste = self.res.get("identification", {}).get("ste")
        if not ste:
            raise NotApplicable()
        labels, amps, errs = [], [], []
        off = ste.get("offset")
        if off and fval(off.get("value")) == fval(off.get("value")):
            labels.append("e0")
            amps.append(abs(fval(off.get("value"))) * 1e6)
            errs.append(2 * fval(off.get("std")) * 1e6)
        terms = [("mesh", t) for t in ste.get("mesh", [])] + \
                [(t.get("shaft", "shaft"), t) for t in ste.get("shaft", [])]
        for kind, t in terms:
            labels.append(f"{kind} {t.get('order')}")
            amps.append(fval(t.get("amplitude")) * 1e6)
            errs.append(2 * max(fval(t.get("cos_std")), fval(t.get("sin_std"))) * 1e6)
        fig, (a, b) = plt.subplots(2, 1, figsize=FIGSIZE, dpi=DPI)  # different x axes
        x = np.arange(len(labels))
        a.bar(x, amps, yerr=errs, capsize=3, color="tab:blue")
        a.set_xticks(x)
        a.set_xticklabels(labels, fontsize=8)
        a.set_ylabel("amplitude [µm] (±2 SE)")
        flag = "" if ste.get("separable", True) else "  — NOT SEPARABLE from the damping"
        cal = ste.get("calibration") or {}  # a streamed run (docs/ste.md)
        span = "shared by the record" if cal.get("whole_record", True) else (
            f"calibrated on {cal.get('segments')} segments "
            f"({fmt(1e3 * fval(cal.get('t_start')), '.3f')}–{fmt(1e3 * fval(cal.get('t_end')), '.3f')} ms), "
            f"held for {cal.get('held_segments')}")
        a.set_title(f"STE spectrum, {span} ({ste.get('damping')} damping){flag}",
                    fontsize=9, color="black" if not flag else "red")
        u = np.linspace(0.0, 2.0, 400)
        e = np.zeros_like(u)
        for t in ste.get("mesh", []):
            h = t.get("order")
            e += fval(t.get("cos")) * np.cos(2 * np.pi * h * u) + \
                fval(t.get("sin")) * np.sin(2 * np.pi * h * u)
        b.plot(u, e * 1e6, lw=1)
        b.set_xlabel("mesh phase u [mesh cycles]")
        b.set_ylabel("mesh-order STE [µm]")
        save(fig, path)

    def metadata_html(self):
        """Run metadata: package version, command line, input file (size, SHA-256), date, options."""
        meta = self.res.get("metadata")
        inp = self.res.get("input", {})
        rows = []
        if not meta:
            rows.append(("run metadata", "none in result.json (written by an older analyze)"))
            rows.append(("input", f"{inp.get('file', '')}"))
        else:
            mi = meta.get("input") or {}
            digest, how = input_sha256(mi)
            size = mi.get("size_bytes")
            rows += [("package", f"{meta.get('package', '')} {meta.get('version', '')}"),
                     ("command line", f"<code>{html.escape(str(meta.get('command_line', '')))}</code>"),
                     ("working directory", html.escape(str(meta.get("working_directory", "")))),
                     ("analysed", html.escape(str(meta.get("date", "")))),
                     ("input file", html.escape(str(mi.get("absolute_path") or mi.get("path", "")))),
                     ("input size", "unknown" if size is None else f"{size:,} bytes".replace(",", " ")),
                     ("input modified", html.escape(str(mi.get("modified") or "unknown"))),
                     ("input SHA-256", (f"<code>{digest}</code> " if digest else "") +
                      f"<small>({html.escape(how)})</small>")]
            opts = meta.get("options") or {}
            if opts:
                rows.append(("options", "<br>".join(
                    f"<code>{html.escape(k)} {html.escape(' '.join(map(str, v)) if isinstance(v, list) else str(v))}</code>"
                    for k, v in opts.items())))
        rows.append(("record", f"{inp.get('samples', '')} samples at {fmt(inp.get('sample_rate'), 'g')} Hz"
                               f", {fmt(1e3 * fval(inp.get('duration')), '.3f')} ms analysed"))
        rows.append(("report written", datetime.datetime.now(datetime.timezone.utc)
                     .strftime("%Y-%m-%dT%H:%M:%SZ")))
        out = ["<table class='meta'>"]
        for k, v in rows:
            out.append(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>")
        out.append("</table>")
        return "\n".join(out)

    def tables_html(self):
        out = []
        ident = self.res.get("identification")
        if self.runs:
            out.append("<h2>Runs</h2><table><tr><th>formulation</th><th>model</th><th>estimator</th>"
                       "<th>C [1/s]</th><th>c0 [N·s/m]</th><th>c1 [N·s/m/(N·m)]</th><th>fit [%]</th>"
                       "<th>segments</th><th>flags</th></tr>")
            for (f, m), r in self.runs.items():
                c = (r.get("constant") or {}).get("C")
                ll = r.get("load_law") or {}
                fit = fval(r.get("response", {}).get("fit_percent"))
                flags = run_flags(r)
                fit_flag = [x for x in flags if x[0] == "negative_fit"]
                c_flag = segment_flags(r["constant"]) if r.get("constant") else []
                out.append(f"<tr{' class=flagged' if flags else ''}><td>{f}</td><td>{m}</td>"
                           f"<td>{r.get('estimator', '')}</td>"
                           f"<td{flag_attr(c_flag)}>{fmt(c, '.1f')}</td><td>{fmt(ll.get('c0'), '.4f')}</td>"
                           f"<td>{fmt(ll.get('c1'), '.6f')}</td><td{flag_attr(fit_flag)}>{fmt(fit, '.2f')}</td>"
                           f"<td>{html.escape(summary_line(r['segments'])) if r.get('segments') else '–'}</td>"
                           f"<td class='text'>{flags_html(flags)}</td></tr>")
            out.append("</table>")
        if ident and ident.get("segments"):
            segs = ident["segments"]
            flagged = [i for i, s in enumerate(segs) if segment_flags(s)]
            shown = range(len(segs)) if len(segs) <= MAX_SEGMENT_ROWS else \
                sorted(set(flagged[:MAX_SEGMENT_ROWS]) | set(range(min(20, len(segs)))))
            out.append(f"<h2>Segments ({html.escape(ident['formulation'])}, {html.escape(ident['model'])}): "
                       f"{html.escape(summary_line(segs))}</h2>")
            if len(shown) < len(segs):
                out.append(f"<p>{len(segs)} segments: the first 20 and the flagged ones are listed "
                           "(all are in result.json and tables/segments.csv).</p>")
            out.append("<table><tr><th>#</th><th>t_start [ms]</th><th>t_end [ms]</th><th>C [1/s]</th>"
                       "<th>C_std [1/s]</th><th>c [N·s/m]</th><th>ξ</th><th>flags</th></tr>")
            for i in shown:
                s = segs[i]
                flags = segment_flags(s)
                cf = [x for x in flags if x[0] in ("not_identifiable", "nonpositive_damping")]
                xf = [x for x in flags if x[0] in ("not_identifiable", "overdamped")]
                out.append(f"<tr{' class=flagged' if flags else ''}><td>{i}</td>"
                           f"<td>{fval(s.get('t_start')) * 1e3:.3f}</td><td>{fval(s.get('t_end')) * 1e3:.3f}</td>"
                           f"<td{flag_attr(cf)}>{fmt(s.get('C'), '.1f')}</td><td>{fmt(s.get('C_std'), '.2g')}</td>"
                           f"<td>{fmt(s.get('c'), '.2f')}</td><td{flag_attr(xf)}>{fmt(s.get('xi'), '.5f')}</td>"
                           f"<td class='text'>{flags_html(flags)}</td></tr>")
            out.append("</table>")
        modes = self.res.get("wavelet", {}).get("modes")
        if modes:
            out.append("<h2>Wavelet modes (as the paper's Table 2)</h2><table><tr><th>mode</th>"
                       "<th>frequency [Hz]</th><th>ξ wavelet</th><th>ξ integral method</th><th>R²</th>"
                       "<th>decay region [ms]</th><th>free decay</th><th>flags</th></tr>")
            for k, m in enumerate(modes):
                flags = mode_flags(m)
                forced = m.get("free_decay") is False
                xi_cell = ("<i>forced line: no damping</i>" if forced else fmt(m.get("damping_ratio"), ".5f"))
                out.append(f"<tr{' class=flagged' if flags else ''}><td>{k + 1}</td>"
                           f"<td>{fmt(m.get('frequency_hz'), '.1f')}</td>"
                           f"<td{flag_attr(flags)}>{xi_cell}</td>"
                           f"<td>{fmt(m.get('integral_damping_ratio'), '.5f')}</td><td>{fmt(m.get('r2'), '.4f')}</td>"
                           f"<td>{fmt(1e3 * fval(m.get('t_start')), '.3f')} – {fmt(1e3 * fval(m.get('t_end')), '.3f')}</td>"
                           f"<td>{'no' if forced else ('yes' if m.get('free_decay') else '–')}</td>"
                           f"<td class='text'>{flags_html(flags)}</td></tr>")
            out.append("</table>")
        wl = self.res.get("wavelet") or {}
        if warnings_of(wl):
            out.append(f"<p class='flag'>Wavelet validation: {flags_html(warnings_of(wl))}</p>")
        return "\n".join(out)


MAX_SEGMENT_ROWS = 200  # longer segment lists show the first 20 and the flagged ones


def summary_line(segments):
    """"8 of 10 segments clean, 2 flagged (codes)", as analyze prints it."""
    codes, flagged = {}, 0
    for s in segments:
        f = segment_flags(s)
        if f:
            flagged += 1
            for c in sorted({c or "warning" for c, _ in f}):
                codes[c] = codes.get(c, 0) + 1
    n = len(segments)
    line = f"{n - flagged} of {n} segment{'s' if n != 1 else ''} clean"
    if flagged:
        line += f", {flagged} flagged (" + ", ".join(f"{c} {k}" for c, k in sorted(codes.items())) + ")"
    return line


def input_sha256(meta_input):
    """(hex digest or None, how it was obtained) of the analysed input file: hashed here, at report
    time, when the file is still readable with the size and modification time recorded by analyze."""
    path = meta_input.get("absolute_path") or meta_input.get("path")
    if not path or not os.path.isfile(path):
        return None, "not computed: the input file is not reachable from here"
    st = os.stat(path)
    if meta_input.get("size_bytes") is not None and st.st_size != meta_input["size_bytes"]:
        return None, "not computed: the input file changed size since the analysis"
    if meta_input.get("modified_unix") is not None and int(st.st_mtime) != meta_input["modified_unix"]:
        return None, "not computed: the input file was modified after the analysis"
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest(), "computed by the report from the file, whose size and modification time match the analysis"


def fmt(v, spec):
    v = fval(v)
    return "–" if not math.isfinite(v) else format(v, spec)


# Marks the page once loaded: data-images / data-images-broken on <body> (read by the browser
# test) and a visible note under every figure that failed to load.
IMAGE_CHECK_JS = """<script>
window.addEventListener('load', function () {
  var imgs = document.images, broken = 0;
  for (var i = 0; i < imgs.length; i++) {
    if (!(imgs[i].complete && imgs[i].naturalWidth > 0)) {
      broken++;
      var p = document.createElement('p');
      p.className = 'flag';
      p.textContent = 'figure failed to load: ' + imgs[i].getAttribute('src');
      imgs[i].parentNode.insertBefore(p, imgs[i].nextSibling);
    }
  }
  document.body.setAttribute('data-images', imgs.length);
  document.body.setAttribute('data-images-broken', broken);
});
</script>"""

STYLE = ("body{font-family:sans-serif;max-width:1250px;margin:auto}table{border-collapse:collapse;margin-bottom:1em}"
         "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}td.text{text-align:left;font-size:90%}"
         "table.meta th,table.meta td{text-align:left}img{width:100%}"
         ".flag{background:#ffd7d7}tr.flagged td:first-child{border-left:4px solid #d00}"
         "p.flag{padding:4px 8px}")


def make_report(result_dir, out_dir=None, quiet=False):
    """Writes the figures and index.html; returns (figures written, notes of skipped ones)."""
    out_dir = out_dir or os.path.join(result_dir, "report")
    os.makedirs(out_dir, exist_ok=True)
    rep = Report(result_dir, out_dir)
    written, notes = [], []
    progress = Progress(len(FIGURES) + 1, not quiet)
    for k, (name, title) in enumerate(FIGURES):
        progress.step(k, name)
        try:
            getattr(rep, name[:-4])(os.path.join(out_dir, name))
            written.append((name, title))
        except NotApplicable:
            plt.close("all")
        except Missing as e:
            notes.append((name, title, str(e)))
            plt.close("all")
    progress.step(len(FIGURES), "index.html (hashing the input)")
    body = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>gear_damping report</title>",
            f"<style>{STYLE}</style></head><body>",
            "<h1>gear_damping report</h1>",
            rep.metadata_html(),
            "<p>Highlighted values should not be trusted as they are: the reason is in the row's "
            "flags (not identifiable, C ≤ 0, ξ ≥ 1, fit &lt; 0, a warning, a wavelet mode that is a "
            "forced line rather than a free decay).</p>",
            rep.tables_html()]
    for name, title in written:
        body.append(f"<h2>{html.escape(title)}</h2><img src='{name}' alt='{html.escape(title)}'>")
    for name, title, why in notes:
        body.append(f"<p><i>{html.escape(title)}: not drawn ({html.escape(why)}).</i></p>")
    body.append(IMAGE_CHECK_JS)
    body.append("</body></html>")
    fd, tmp = tempfile.mkstemp(dir=out_dir, suffix=".partial")
    with os.fdopen(fd, "w") as f:
        f.write("\n".join(body))
    os.chmod(tmp, 0o644)
    os.replace(tmp, os.path.join(out_dir, "index.html"))
    progress.finish()
    return written, notes


def main(argv):
    import argparse
    p = argparse.ArgumentParser(description="Figures and index.html from an analysis result directory.")
    p.add_argument("result_dir")
    p.add_argument("--out", help="output directory (default RESULT_DIR/report)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line on stderr")
    a = p.parse_args(argv)
    if not os.path.isdir(a.result_dir):
        print(f"report: {a.result_dir}: no such directory", file=sys.stderr)
        return 2
    if not os.path.isfile(os.path.join(a.result_dir, "result.json")):
        print(f"report: {a.result_dir}: no result.json (run analyze --output first)", file=sys.stderr)
        return 2
    try:
        written, notes = make_report(a.result_dir, a.out, a.quiet)
    except (OSError, ValueError, KeyError) as e:
        print(f"report: {a.result_dir}: {e}", file=sys.stderr)
        return 2
    for name, _, why in notes:
        print(f"report: warning: {name} skipped ({why})", file=sys.stderr)
    out = a.out or os.path.join(a.result_dir, "report")
    print(f"report: {len(written)} figures, {os.path.join(out, 'index.html')}")
    return 0

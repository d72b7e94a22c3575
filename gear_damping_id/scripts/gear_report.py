"""Figures and an HTML page from an analysis result directory (see docs/report.md).

RESULT_DIR holds signal.csv, result.json and tables/ as written by scripts/demo.sh and
`analyze --output RESULT_DIR/result.json --csv-out RESULT_DIR/tables`. Every figure is a
1200 x 750 px PNG; a figure whose inputs are missing is skipped with a note."""
import csv
import html
import json
import math
import os
import sys
import tempfile

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
    ("fig09_response_piecewise.png", "Fig. 9: modeled vs observed DTE, piecewise damping"),
    ("fig09b_response_load_law.png", "Modeled vs observed DTE, load-law damping"),
    ("fig10_scalogram.png", "Fig. 10: Morlet scalogram with the cone of influence"),
    ("fig11_spectrum.png", "Fig. 11: spectrum with the picked modes"),
    ("fig12_envelopes.png", "Fig. 12: wavelet envelopes and their decay fits"),
]


class Missing(Exception):
    """An input a figure needs is absent."""


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


def new_fig(nrows=1):
    fig, axes = plt.subplots(nrows, 1, figsize=FIGSIZE, dpi=DPI, sharex=nrows > 1, squeeze=False)
    return fig, [a[0] for a in axes]


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
        t, y, yh = col(rows, "time"), col(rows, "observed"), col(rows, "modeled")
        fig, (a,) = new_fig()
        a.plot(t * 1e3, y * 1e6, lw=1.2, label="observed")
        lim = np.nanmax(np.abs(y)) * 1e6
        a.plot(t * 1e3, np.clip(yh * 1e6, -3 * lim, 3 * lim), "--", lw=1.0,
               label=f"modeled, {label} (fit {fit:.1f} %)")
        a.set_ylim(-1.5 * lim if np.nanmin(y) < 0 else 0, 1.5 * lim)
        a.set_xlabel("time [ms]")
        a.set_ylabel("DTE y [µm]")
        a.legend(loc="upper right")
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

    # Fig. 10
    def fig10_scalogram(self, path):
        p = os.path.join(self.tables, "wavelet_scalogram.csv")
        if not os.path.exists(p):
            raise Missing("wavelet_scalogram.csv not found")
        m = np.loadtxt(p, delimiter=",", comments="#")
        times, freqs, coi, w = m[0, 2:], m[1:, 0], m[1:, 1], m[1:, 2:]
        fig, (a,) = new_fig()
        pc = a.pcolormesh(times * 1e3, freqs, w * 1e6, shading="auto", cmap="viridis")
        fig.colorbar(pc, ax=a, label="|W| [µm]")
        t0, t1 = times[0], times[-1]
        left = np.minimum(t0 + coi, t1)
        right = np.maximum(t1 - coi, t0)
        a.fill_betweenx(freqs, t0 * 1e3, left * 1e3, color="w", alpha=0.35, hatch="//", lw=0)
        a.fill_betweenx(freqs, right * 1e3, t1 * 1e3, color="w", alpha=0.35, hatch="//", lw=0)
        a.set_yscale("log")
        a.set_xlabel("time [ms]")
        a.set_ylabel("frequency [Hz]")
        save(fig, path)

    # Fig. 11
    def fig11_spectrum(self, path):
        rows = read_csv(os.path.join(self.tables, "wavelet_spectrum.csv"))
        kind = np.array([r["kind"] for r in rows])
        f, p = col(rows, "frequency_hz"), col(rows, "power")
        fig, (a,) = new_fig()
        psd = (kind == "psd") & (f > 0)
        a.loglog(f[psd], p[psd], lw=0.6, color="0.6", label="PSD [m²/Hz]")
        a.set_xlabel("frequency [Hz]")
        a.set_ylabel("PSD [m²/Hz]")
        b = a.twinx()
        sc = kind == "scalogram"
        b.loglog(f[sc], p[sc], color="C0", lw=1.5, label="scale-averaged scalogram [m²]")
        b.set_ylabel("time-averaged |W|² [m²]")
        for m in self.res.get("wavelet", {}).get("modes", []):
            if m.get("frequency_hz") is not None:
                a.axvline(m["frequency_hz"], color="C3", ls="--", lw=1)
                b.annotate(f"{m['frequency_hz']:.0f} Hz", (m["frequency_hz"], np.nanmax(p[sc])),
                           color="C3", rotation=90, va="top", ha="right", fontsize=8)
        a.legend(loc="lower left")
        b.legend(loc="upper right")
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
            a.semilogy(t[sel] * 1e3, e[sel] * 1e6, lw=1, color=f"C{k}",
                       label=f"{float(m['frequency_hz']):.0f} Hz: ξ = {float(m['damping_ratio']):.4f}, "
                             f"R² = {float(m['r2']):.3f}")
            sigma, t0, t1 = float(m["sigma_per_s"]), float(m["t_start_s"]), float(m["t_end_s"])
            if all(math.isfinite(v) for v in (sigma, t0, t1)):
                reg = sel & (t >= t0) & (t <= t1)
                if reg.any():
                    a0 = np.mean(np.log(e[reg]) + sigma * t[reg])  # intercept for the known slope
                    tt = np.linspace(t0, t1, 50)
                    a.semilogy(tt * 1e3, np.exp(a0 - sigma * tt) * 1e6, "k--", lw=1.5)
                    a.axvspan(t0 * 1e3, t1 * 1e3, color=f"C{k}", alpha=0.08)
        a.plot([], [], "k--", label="fit ln|W| = a − σt (decay region shaded)")
        a.set_xlabel("time [ms]")
        a.set_ylabel("envelope |W(f_mode, t)| [µm]")
        a.legend(loc="best", fontsize=8)
        save(fig, path)

    def tables_html(self):
        out = []
        ident = self.res.get("identification")
        if self.runs:
            out.append("<h2>Runs</h2><table><tr><th>formulation</th><th>model</th><th>estimator</th>"
                       "<th>C [1/s]</th><th>c0 [N·s/m]</th><th>c1 [N·s/m/(N·m)]</th><th>fit [%]</th></tr>")
            for (f, m), r in self.runs.items():
                c = (r.get("constant") or {}).get("C")
                ll = r.get("load_law") or {}
                fit = fval(r.get("response", {}).get("fit_percent"))
                out.append(f"<tr><td>{f}</td><td>{m}</td><td>{r.get('estimator', '')}</td>"
                           f"<td>{fmt(c, '.1f')}</td><td>{fmt(ll.get('c0'), '.4f')}</td>"
                           f"<td>{fmt(ll.get('c1'), '.6f')}</td><td>{fmt(fit, '.2f')}</td></tr>")
            out.append("</table>")
        if ident and ident.get("segments"):
            out.append(f"<h2>Segments ({html.escape(ident['formulation'])}, {html.escape(ident['model'])})</h2>"
                       "<table><tr><th>t_start [ms]</th><th>t_end [ms]</th><th>C [1/s]</th><th>C_std [1/s]</th>"
                       "<th>c [N·s/m]</th><th>ξ</th><th>note</th></tr>")
            for s in ident["segments"]:
                out.append(f"<tr><td>{s['t_start'] * 1e3:.3f}</td><td>{s['t_end'] * 1e3:.3f}</td>"
                           f"<td>{fmt(s.get('C'), '.1f')}</td><td>{fmt(s.get('C_std'), '.2g')}</td>"
                           f"<td>{fmt(s.get('c'), '.2f')}</td><td>{fmt(s.get('xi'), '.5f')}</td>"
                           f"<td>{html.escape(s.get('reason', ''))}</td></tr>")
            out.append("</table>")
        modes = self.res.get("wavelet", {}).get("modes")
        if modes:
            out.append("<h2>Wavelet modes (paper Table 2)</h2><table><tr><th>frequency [Hz]</th>"
                       "<th>ξ wavelet</th><th>ξ integral</th><th>R²</th><th>decay region [ms]</th><th>warning</th></tr>")
            for m in modes:
                out.append(f"<tr><td>{fmt(m.get('frequency_hz'), '.1f')}</td><td>{fmt(m.get('damping_ratio'), '.5f')}</td>"
                           f"<td>{fmt(m.get('integral_damping_ratio'), '.5f')}</td><td>{fmt(m.get('r2'), '.4f')}</td>"
                           f"<td>{fmt(1e3 * fval(m.get('t_start')), '.3f')} – {fmt(1e3 * fval(m.get('t_end')), '.3f')}</td>"
                           f"<td>{'' if m.get('free_decay', True) else '<b>forced line</b> '}"
                           f"{html.escape('; '.join(w['code'] + ': ' + w['text'] for w in m.get('warnings', [])))}</td></tr>")
            out.append("</table>")
        return "\n".join(out)


def fmt(v, spec):
    v = fval(v)
    return "–" if not math.isfinite(v) else format(v, spec)


def make_report(result_dir, out_dir=None):
    """Writes the figures and index.html; returns (figures written, notes of skipped ones)."""
    out_dir = out_dir or os.path.join(result_dir, "report")
    os.makedirs(out_dir, exist_ok=True)
    rep = Report(result_dir, out_dir)
    written, notes = [], []
    for name, title in FIGURES:
        try:
            getattr(rep, name[:-4])(os.path.join(out_dir, name))
            written.append((name, title))
        except Missing as e:
            notes.append((name, title, str(e)))
            plt.close("all")
    body = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>gear_damping report</title>",
            "<style>body{font-family:sans-serif;max-width:1250px;margin:auto}table{border-collapse:collapse}"
            "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}img{width:100%}</style></head><body>",
            "<h1>gear_damping report</h1>",
            f"<p>Input: {html.escape(str(rep.res.get('input', {}).get('file', '')))}, "
            f"{rep.res.get('input', {}).get('samples', '')} samples at "
            f"{fmt(rep.res.get('input', {}).get('sample_rate'), 'g')} Hz.</p>",
            rep.tables_html()]
    for name, title in written:
        body.append(f"<h2>{html.escape(title)}</h2><img src='{name}' alt='{html.escape(title)}'>")
    for name, title, why in notes:
        body.append(f"<p><i>{html.escape(title)}: not drawn ({html.escape(why)}).</i></p>")
    body.append("</body></html>")
    fd, tmp = tempfile.mkstemp(dir=out_dir, suffix=".partial")
    with os.fdopen(fd, "w") as f:
        f.write("\n".join(body))
    os.chmod(tmp, 0o644)
    os.replace(tmp, os.path.join(out_dir, "index.html"))
    return written, notes


def main(argv):
    import argparse
    p = argparse.ArgumentParser(description="Figures and index.html from an analysis result directory.")
    p.add_argument("result_dir")
    p.add_argument("--out", help="output directory (default RESULT_DIR/report)")
    a = p.parse_args(argv)
    if not os.path.isdir(a.result_dir):
        print(f"report: {a.result_dir}: no such directory", file=sys.stderr)
        return 2
    if not os.path.isfile(os.path.join(a.result_dir, "result.json")):
        print(f"report: {a.result_dir}: no result.json (run analyze --output first)", file=sys.stderr)
        return 2
    try:
        written, notes = make_report(a.result_dir, a.out)
    except (OSError, ValueError, KeyError) as e:
        print(f"report: {a.result_dir}: {e}", file=sys.stderr)
        return 2
    for name, _, why in notes:
        print(f"report: warning: {name} skipped ({why})", file=sys.stderr)
    out = a.out or os.path.join(a.result_dir, "report")
    print(f"report: {len(written)} figures, {os.path.join(out, 'index.html')}")
    return 0

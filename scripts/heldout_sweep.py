#!/usr/bin/python3
"""Random held-out gear cases: simulate, analyze, and check every segment against the truth.

Each case draws its own gear pair (17-40 pinion teeth, ratio 1-3, inertias, base radii),
mesh stiffness (square, trapezoid or Fourier; levels 2e8-8e8 N/m, contact ratio 1.2-1.9),
speed (800-6000 rpm), load (constant, sine, step, ramp), damping law (constant ratio,
load-dependent, load-linear, piecewise in time), sample rate (250 kHz-1 MHz, raised to 1 MHz
when the simulator asks for more) and noise (none, 40, 30 or 20 dB), simulates 50 ms with
`simulate`, analyses it with `analyze` (default options unless given after `--`), and compares
each identifiable segment's C with the time-mean of the true c(t)/Me over the segment (the
damping at the segment's mean load for the laws linear in the load). Segments that straddle a
step of a piecewise-in-time truth are left out. A segment is "wrong" when neither it nor its run
carries a warning and it is more than 4 standard errors and more than 0.05 % (the noise-free
accuracy bar) from the truth. Prints one line per case and a JSON summary: counts (with the
number of noisy clean segments expected beyond 4 C_std by chance), and per noise level the share
of clean segments within +-1.96 C_std (95 % if calibrated) and the rms of (C - truth) / C_std,
and the clean, flagged and wrong counts per true stiffness shape (--stiffness: only that shape).

  scripts/heldout_sweep.py --bin-dir WS/devel/lib/gear_damping --cases 300 --seed 3000 \\
      --out /tmp/sweep [-- --refine never]

--check chooses what is compared with the truth (repeat it to check several outputs of the same
runs; the analyze options after -- must ask for them):
- segments (the default): the piecewise segments as above, every formulation and stiffness shape
  (`-- --formulation greybox --stiffness-shape fourier:2`);
- constant (`-- --model constant`): identification.constant's C against the time mean of the
  true c/Me over the analysed range, where the true damping is constant there; where it varies
  (load-dependent or load-linear damping under a varying load, piecewise in time) the constant
  model does not describe it, and the run counts as misfit_flagged (the constant or its run
  carries a warning), misfit_segments_flagged (only some of its segments do) or misfit_clean
  (none; misfit_clean_far: also > 4 C_std and 0.05 % from the time mean);
- load_law (`-- --model load_law`): c0 and c1 against the least-squares line of the true c(t)
  on T1(t) over the analysed range (exact for the constant, load-dependent and load-linear laws;
  c1 = 0 under a constant load); a truth off the line (piecewise in time) is a misfit as above.
  Noise-free bar: the line's error over the record's load range beyond 0.05 % of the mean c;
- curve (`-- --formulation greybox --stiffness-shape fourier:H`, H >= 2, `--stiffness fourier`):
  each clean segment's stiffness_curve against the least-squares coefficients of the true
  stiffness on the same basis of the mesh phase (exact: the drawn Fourier truths have two
  harmonics); bar 0.01 % of the mean stiffness. Every coefficient's z enters the coverage.
--extras also draws the simulator options the base draw leaves at their defaults (torsional
dynamics, 1-4 RK4 substeps, a speed ramp, a periodic trapezoid load), from a stream of its own,
so the base draw of a seed is the same with and without it.
--drop-mesh-phase analyses each record without its mesh_phase column (the switch timing check,
docs/trust.md "Switches between samples without `mesh_phase`").

Used for docs/method.md section 4 (Refinement: clean data) and docs/trust.md (integral_std,
"Held-out sweeps of the shared models, greybox shapes and simulator options").
"""
import argparse
import bisect
import csv
import json
import math
import os
import random
import subprocess
import sys


def gear_yaml(r):
    """A random case as the simulator's YAML, and a short description."""
    z1 = r.randint(17, 40)
    z2 = r.randint(z1, 3 * z1)
    r1 = r.uniform(0.03, 0.07)
    kmax = r.uniform(2e8, 8e8)
    kmin = kmax * r.uniform(0.4, 0.75)
    eps = r.uniform(1.2, 1.9)
    shape = r.choice(['square', 'square', 'trapezoid', 'fourier'])
    mesh = (f"  stiffness_model: {shape}\n  k_max: {kmax}\n  k_min: {kmin}\n"
            f"  contact_ratio: {eps}\n  initial_phase: {r.random()}\n")
    if shape == 'trapezoid':
        mesh += f"  transition_fraction: {r.uniform(0.1, 0.95) * min(eps - 1, 2 - eps)}\n"
    if shape == 'fourier':
        a = 0.5 * (kmax - kmin)
        mesh += (f"  k_mean: {0.5 * (kmax + kmin)}\n"
                 f"  fourier_cos: [{a * r.uniform(0.3, 0.8)}, {a * r.uniform(0, 0.3)}]\n"
                 f"  fourier_sin: [{a * r.uniform(0, 0.3)}, 0.0]\n")
    rpm = r.uniform(800, 6000)
    # Each profile's text draws its own numbers, and only the chosen one is drawn (lambdas).
    load_kind = r.choice(['constant', 'sine', 'step', 'ramp'])
    mean = r.uniform(30, 400)
    load = {
        'constant': lambda: f"  profile: constant\n  mean: {mean}\n",
        'sine': lambda: (f"  profile: sine\n  mean: {mean}\n"
                         f"  amplitude: {mean * r.uniform(0.05, 0.6)}\n"
                         f"  frequency: {r.uniform(10, 300)}\n"),
        'step': lambda: (f"  profile: step\n  initial: {mean}\n"
                         f"  final: {mean * r.uniform(0.5, 1.5)}\n"
                         f"  step_time: {r.uniform(0.005, 0.045)}\n"),
        'ramp': lambda: (f"  profile: ramp\n  initial: {mean}\n"
                         f"  final: {mean * r.uniform(0.5, 1.5)}\n  ramp_start: 0.0\n"
                         "  ramp_end: 0.05\n"),
    }[load_kind]()
    law = r.choice(['constant', 'load_dependent', 'load_linear', 'piecewise'])
    xi = r.uniform(0.02, 0.12)
    damping = f"  model: {law}\n" + {
        'constant': lambda: f"  ratio: {xi}\n",
        'load_dependent': lambda: f"  ratio: {xi}\n  load_sensitivity: {r.uniform(0, 1)}\n",
        'load_linear': lambda: f"  c0: {r.uniform(100, 600)}\n  c1: {r.uniform(0, 3)}\n",
        'piecewise': lambda: (f"  ratios: [{xi}, {xi * r.uniform(0.6, 1.4)}, "
                              f"{xi * r.uniform(0.6, 1.4)}]\n  times: [0.0, "
                              f"{r.uniform(0.01, 0.02)}, {r.uniform(0.025, 0.04)}]\n"),
    }[law]()
    rate = r.choice([2.5e5, 5e5, 1e6])
    snr = r.choice(['.inf', '40', '30', '20'])
    text = (f"pinion:\n  teeth: {z1}\n  inertia: {r.uniform(1e-4, 1e-3)}\n  base_radius: {r1}\n"
            f"gear:\n  teeth: {z2}\n  inertia: {r.uniform(2e-3, 2e-2)}\n"
            f"  base_radius: {r1 * z2 / z1}\nmesh:\n{mesh}"
            f"speed:\n  profile: constant\n  pinion_rpm: {rpm}\nload:\n{load}damping:\n{damping}"
            f"simulation:\n  duration: 0.05\n  sample_rate: {rate}\n  integrator: rk4\n"
            f"  substeps: 1\n  dynamics: reduced\n  noise_snr_db: {snr}\n"
            f"  seed: {r.randint(1, 10**6)}\n")
    return text, {'stiffness': shape, 'load': load_kind, 'damping': law, 'rate': rate,
                  'snr': snr, 'rpm': round(rpm)}


def add_extras(text, info, r):
    """Simulator options the base draw leaves at their defaults, drawn from their own stream r
    (so a case's base draw is the same with and without --extras): the torsional two-DOF
    dynamics, 1-4 RK4 substeps, a speed ramp (+-30 % over the record) and a periodic
    trapezoid load in place of the drawn profile (each with probability 1/2)."""
    dyn = r.choice(['reduced', 'torsional'])
    sub = r.randint(1, 4)
    text = text.replace('dynamics: reduced', f'dynamics: {dyn}')
    text = text.replace('substeps: 1', f'substeps: {sub}')
    info.update(dynamics=dyn, substeps=sub)
    if r.random() < 0.5:
        head, rest = text.split('speed:\n', 1)
        rpm = float(rest.split('pinion_rpm: ', 1)[1].split('\n', 1)[0])
        text = (head + f"speed:\n  profile: ramp\n  pinion_rpm: {rpm}\n"
                f"  end_rpm: {rpm * r.uniform(0.7, 1.3)}\n  ramp_time: 0.05\n"
                + rest.split('\n', 2)[2])
        info['speed'] = 'ramp'
    if r.random() < 0.5:
        head, rest = text.split('load:\n', 1)
        low = r.uniform(30, 300)
        period = r.uniform(0.004, 0.02)
        text = (head + f"load:\n  profile: trapezoid\n  low: {low}\n"
                f"  high: {low * r.uniform(1.1, 2.0)}\n  rise: {period * 0.2}\n"
                f"  hold: {period * 0.3}\n  fall: {period * 0.2}\n  period: {period}\n"
                + 'damping:\n' + rest.split('damping:\n', 1)[1])
        info['load'] = 'trapezoid'
    return text, info


def run(cmd):
    return subprocess.run(cmd, capture_output=True, text=True)


def simulate(bin_dir, name, text, info, free=False):
    """Writes NAME.yaml and NAME.csv; None when the simulator refuses the case."""
    for _ in range(2):
        with open(name + '.yaml', 'w') as f:
            f.write(text)
        p = run([os.path.join(bin_dir, 'simulate'), '-q', '--config', name + '.yaml',
                 '--output', name + '.csv'] + (['--free-response'] if free else []))
        if p.returncode == 0:
            return True
        if 'natural frequency' not in p.stderr:
            break
        text = text.replace(f"sample_rate: {info['rate']}", 'sample_rate: 1000000.0')
        info['rate'] = 1e6
    print('simulate refused', name, p.stderr.strip()[:200], file=sys.stderr)
    return False


def read_rows(path):
    """The CSV at PATH as a list of rows (the header first)."""
    with open(path) as f:
        return list(csv.reader(f))


def write_rows(path, rows):
    """Writes ROWS to the CSV at PATH (as the simulator does: \\n line ends)."""
    with open(path, 'w', newline='') as f:
        csv.writer(f, lineterminator='\n').writerows(rows)


def drop_column(path, name):
    """Rewrites the CSV at PATH without its column NAME (if it has one)."""
    rows = read_rows(path)
    if not rows or name not in rows[0]:
        return
    k = rows[0].index(name)
    write_rows(path, [row[:k] + row[k + 1:] for row in rows])


def add_torque_glitches(path, r, count):
    """Adds COUNT one-sample glitches of 20-200 N*m (random sign) to the torque column of the
    CSV at PATH, at random samples; returns their (time, size)."""
    rows = read_rows(path)
    k = rows[0].index('torque')
    out = []
    for _ in range(count):
        i = r.randrange(2, len(rows) - 1)
        g = r.choice((-1, 1)) * r.uniform(20.0, 200.0)
        rows[i][k] = repr(float(rows[i][k]) + g)
        out.append((float(rows[i][0]), g))
    write_rows(path, rows)
    return out


def quantise_torque(path, q):
    """Rounds the torque column of the CSV at PATH to multiples of Q N*m (no dither)."""
    rows = read_rows(path)
    k = rows[0].index('torque')
    for row in rows[1:]:
        row[k] = repr(round(float(row[k]) / q) * q)
    write_rows(path, rows)


def read_truth(path, names=('time', 'damping')):
    """The named columns of a simulated CSV (time and damping [N*s/m] by default)."""
    with open(path) as f:
        rows = csv.reader(f)
        head = next(rows)
        idx = [head.index(n) for n in names]
        cols = [[] for _ in names]
        for row in rows:
            for col, i in zip(cols, idx):
                col.append(float(row[i]))
    return cols


def segment_truth(t, c, t0, t1, me):
    """(mean of c/Me over [t0, t1), whether c varies there)."""
    vals = c[bisect.bisect_left(t, t0 - 1e-12):bisect.bisect_left(t, t1 - 1e-12)]  # t ascending
    if not vals:
        return math.nan, False
    mean = sum(vals) / len(vals)
    return mean / me, max(vals) - min(vals) > 1e-9 * abs(mean)


def tally_case(result, t, c, law, snr, totals, z_by_snr, by_shape):
    wrong = []
    shape_totals = by_shape.setdefault(totals['_shape'], dict.fromkeys(['clean', 'flagged',
                                                                          'wrong'], 0))
    for run_ in result['runs']:
        me = run_['equivalent_mass']
        run_warned = bool(run_['warnings'])  # e.g. integral_std: every C_std of the run
        for s in run_['segments']:
            totals['segments'] += 1
            if not s['identifiable']:
                totals['not_identifiable'] += 1
                continue
            truth, varies = segment_truth(t, c, s['t_start'], s['t_end'], me)
            if law == 'piecewise' and varies:
                totals['straddling'] += 1
                continue
            if s['warnings'] or run_warned:
                totals['flagged'] += 1
                shape_totals['flagged'] += 1
                continue
            totals['clean'] += 1
            shape_totals['clean'] += 1
            err = s['C'] - truth
            z = err / s['C_std'] if s['C_std'] > 0 else math.inf
            z_by_snr.setdefault(snr, []).append(z)
            if abs(z) > 4 and abs(err) > 5e-4 * abs(truth):
                totals['wrong'] += 1
                shape_totals['wrong'] += 1
                wrong.append((round(s['t_start'], 4), round(err / truth, 5), round(z, 1)))
    return wrong


def new_counts():
    return dict.fromkeys(['clean', 'flagged', 'wrong', 'not_identifiable', 'misfit_flagged',
                          'misfit_segments_flagged', 'misfit_clean', 'misfit_clean_far'], 0)


def range_values(t, col, t0, t1):
    return col[bisect.bisect_left(t, t0 - 1e-12):bisect.bisect_left(t, t1 - 1e-12)]


def judge(counts, zs, errs, bars, snr, z_by_snr, wrong, tag):
    """Tallies one clean estimate (several numbers: z-scores, errors and noise-free bars); a
    wrong one is listed with its z-scores and its errors in units of the bar."""
    counts['clean'] += 1
    for z in zs:
        z_by_snr.setdefault(snr, []).append(z)
    if any(abs(z) > 4 and abs(e) > b for z, e, b in zip(zs, errs, bars)):
        counts['wrong'] += 1
        wrong.append((tag, [round(z, 1) for z in zs], [float(f'{e / b:.3g}')
                                                      for e, b in zip(errs, bars)]))


def misfit(counts, warned, segments, z, far, wrong, tag):
    """A shared model the truth does not follow: flagged where the user reads it, only on some
    of its run's segments, or not at all (clean; 'far' when beyond 4 std and the bar from the
    truth's mean)."""
    if warned:
        counts['misfit_flagged'] += 1
    elif any(s['warnings'] for s in segments):
        counts['misfit_segments_flagged'] += 1
    else:
        counts['misfit_clean'] += 1
        counts['misfit_clean_far'] += far
        wrong.append(('misfit ' + tag, round(z, 1)))


def tally_constant(result, cols, snr, counts, z_by_snr):
    """--check constant: identification.constant's C against the time mean of the true c/Me over
    the analysed range; exact when the true damping is constant there, else a misfit."""
    t, c = cols[0], cols[1]
    wrong = []
    for run_ in result['runs']:
        if run_['model'] != 'constant':
            continue
        k = run_['constant']
        if not k['identifiable']:
            counts['not_identifiable'] += 1
            continue
        vals = range_values(t, c, k['t_start'], k['t_end'])
        mean = sum(vals) / len(vals) / run_['equivalent_mass']
        err = k['C'] - mean
        z = err / k['C_std'] if k['C_std'] > 0 else math.inf
        warned = bool(k['warnings'] or run_['warnings'])
        if max(vals) - min(vals) > 1e-9 * abs(mean * run_['equivalent_mass']):
            far = abs(z) > 4 and abs(err) > 5e-4 * abs(mean)
            misfit(counts, warned, run_['segments'], z, far, wrong, run_['formulation'])
        elif warned:
            counts['flagged'] += 1
        else:
            judge(counts, [z], [err], [5e-4 * abs(mean)], snr, z_by_snr, wrong,
                  run_['formulation'])
    return wrong


def linear_truth(t, c, torque, t0, t1):
    """(c0, c1, rms of c - c0 - c1*T, T mean, T min, T max) of the true damping over [t0, t1);
    c1 = 0 when the load does not vary there."""
    cv, tv = range_values(t, c, t0, t1), range_values(t, torque, t0, t1)
    n = len(cv)
    tm, cm = sum(tv) / n, sum(cv) / n
    stt = sum((x - tm) ** 2 for x in tv)
    c1 = sum((x - tm) * (y - cm) for x, y in zip(tv, cv)) / stt if stt > 1e-18 * n * tm**2 else 0
    c0 = cm - c1 * tm
    rms = math.sqrt(sum((y - c0 - c1 * x) ** 2 for x, y in zip(tv, cv)) / n)
    return c0, c1, rms, tm, min(tv), max(tv)


def tally_load_law(result, cols, snr, counts, z_by_snr):
    """--check load_law: c0, c1 against the least-squares line of the true c(t) on T1(t) over
    the analysed range, exact for the constant, load_linear and load_dependent laws; a truth
    off that line (piecewise in time) is a misfit. Noise-free bar: the line's error over the
    record's load range beyond 0.05 % of the mean damping."""
    t, c, torque = cols
    wrong = []
    for run_ in result['runs']:
        if run_['model'] != 'load_law':
            continue
        law = run_['load_law']
        if not law['identifiable']:
            counts['not_identifiable'] += 1
            continue
        segs = run_['segments']
        c0, c1, rms, tm, tlo, thi = linear_truth(t, c, torque, segs[0]['t_start'],
                                                 segs[-1]['t_end'])
        cm = c0 + c1 * tm
        e0, e1 = law['c0'] - c0, law['c1'] - c1
        zs = [e / sd if sd and sd > 0 else math.inf
              for e, sd in ((e0, law['c0_std']), (e1, law['c1_std']))]
        line_err = max(abs(e0 + e1 * tlo), abs(e0 + e1 * thi))
        if rms > 1e-9 * abs(cm):
            far = any(abs(z) > 4 for z in zs) and line_err > 5e-4 * abs(cm)
            misfit(counts, bool(run_['warnings']), segs, max(zs, key=abs), far, wrong,
                   run_['formulation'])
        elif run_['warnings']:
            counts['flagged'] += 1
        else:
            bar = 5e-4 * abs(cm)
            judge(counts, zs, [line_err, line_err], [bar, bar], snr, z_by_snr, wrong,
                  run_['formulation'])
    return wrong


def curve_truth(phase, k, shape_n):
    """Least-squares coefficients of the true stiffness on the fourier:H basis of the mesh
    phase (mean, cos 1, sin 1, ...): exact for a Fourier truth of at most H harmonics."""
    m = 2 * shape_n + 1
    ata = [[0.0] * m for _ in range(m)]
    atb = [0.0] * m
    for u, y in zip(phase, k):
        row = [1.0]
        for h in range(1, shape_n + 1):
            row += [math.cos(2 * math.pi * h * u), math.sin(2 * math.pi * h * u)]
        for i in range(m):
            atb[i] += row[i] * y
            for j in range(m):
                ata[i][j] += row[i] * row[j]
    for i in range(m):  # Gauss-Jordan; ata is well conditioned (many periods)
        piv = ata[i][i]
        for j in range(m):
            if j != i:
                f = ata[j][i] / piv
                ata[j] = [a - f * b for a, b in zip(ata[j], ata[i])]
                atb[j] -= f * atb[i]
    return [atb[i] / ata[i][i] for i in range(m)]


def tally_curve(result, cols, snr, counts, z_by_snr):
    """--check curve: greybox fourier:H stiffness curves (H >= the truth's 2 harmonics) on a
    Fourier truth against the true coefficients over each clean segment; bar 0.01 % of the
    mean stiffness (the greybox levels' noise-free bar)."""
    t, phase, k = cols
    wrong = []
    for run_ in result['runs']:
        shape = run_.get('stiffness_shape', '')
        if not shape.startswith('fourier:'):
            continue
        for s in run_['segments']:
            if not s['identifiable']:
                counts['not_identifiable'] += 1
                continue
            if s['warnings'] or run_['warnings']:
                counts['flagged'] += 1
                continue
            truth = curve_truth(range_values(t, phase, s['t_start'], s['t_end']),
                                range_values(t, k, s['t_start'], s['t_end']),
                                int(shape.split(':')[1]))
            errs = [a - b for a, b in zip(s['stiffness_curve'], truth)]
            zs = [e / sd if sd > 0 else math.inf for e, sd in zip(errs, s['stiffness_curve_std'])]
            judge(counts, zs, errs, [1e-4 * truth[0]] * len(errs), snr, z_by_snr, wrong,
                  round(s['t_start'], 4))
    return wrong


def tally_wavelet(result, cols, snr, counts, z_by_snr):
    """--check wavelet (the record is the case's free response, simulate --free-response, and
    analyze runs with --wavelet): every mode with a damping ratio and no warning against the true
    xi = c/(2 Me omega0) averaged over its decay region with the fit's weight exp(-2 sigma t)
    (docs/wavelet.md); wrong beyond the gear case's 10 % bar (no standard error is reported)."""
    t, c = cols
    wrong = []
    ident = result['identification']
    w0me = 2.0 * ident['omega0'] * ident['equivalent_mass']
    for m in result.get('wavelet', {}).get('modes', []):
        xi = m['damping_ratio']
        if xi is None or not m['free_decay']:
            counts['not_identifiable'] += 1
            continue
        if m['warnings']:
            counts['flagged'] += 1
            continue
        i0, i1 = bisect.bisect_left(t, m['t_start']), bisect.bisect_right(t, m['t_end'])
        wts = [math.exp(-2.0 * m['sigma'] * (t[i] - t[i0])) for i in range(i0, i1)]
        truth = sum(wv * c[i] for wv, i in zip(wts, range(i0, i1))) / sum(wts) / w0me
        rel = (xi - truth) / truth
        z_by_snr.setdefault(snr, []).append(rel / 0.1)  # in units of the 10 % bar
        counts['clean'] += 1
        if abs(rel) > 0.1:
            counts['wrong'] += 1
            wrong.append((round(m['frequency_hz']), round(xi, 5), round(truth, 5)))
    return wrong


CHECKS = {'constant': (tally_constant, ('time', 'damping')),
          'load_law': (tally_load_law, ('time', 'damping', 'torque')),
          'curve': (tally_curve, ('time', 'mesh_phase', 'stiffness')),
          'wavelet': (tally_wavelet, ('time', 'damping'))}


def coverage_of(z_by_snr):
    coverage = {}
    for snr, zs in sorted(z_by_snr.items()):
        finite = [z for z in zs if math.isfinite(z)]
        coverage[snr] = {
            'clean': len(zs),
            'within_1.96_se': sum(abs(z) <= 1.96 for z in zs) / len(zs),
            'rms_z': math.sqrt(sum(z * z for z in finite) / len(finite)) if finite else None,
        }
    return coverage


def analyze_case(a, seed):
    """Simulates and analyses case SEED; (info, result JSON, CSV name) or None."""
    r = random.Random(seed)
    text, info = gear_yaml(r)
    if a.stiffness and info['stiffness'] != a.stiffness:
        return None
    if a.extras:
        text, info = add_extras(text, info, random.Random(seed + 7_000_003))
    name = os.path.join(a.out, f'case{seed}')
    if not simulate(a.bin_dir, name, text, info, 'wavelet' in (a.check or [])):
        return None
    if a.drop_mesh_phase:
        drop_column(name + '.csv', 'mesh_phase')
    if a.torque_quantum:
        quantise_torque(name + '.csv', a.torque_quantum)
    if a.torque_glitches:
        info['glitches'] = add_torque_glitches(name + '.csv', random.Random(seed + 9_000_011),
                                               a.torque_glitches)
    p = run([os.path.join(a.bin_dir, 'analyze'), '-q', '--input', name + '.csv', '--params',
             name + '.yaml', '--output', name + '.json'] + a.analyze_args)
    if p.returncode != 0:
        print('analyze failed', seed, p.returncode, p.stderr.strip()[:300])
        return None
    with open(name + '.json') as f:
        return info, json.load(f), name + '.csv'


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--bin-dir', required=True, help='directory holding simulate and analyze')
    ap.add_argument('--cases', type=int, default=100)
    ap.add_argument('--seed', type=int, default=1, help='first case seed (case i: seed + i)')
    ap.add_argument('--out', required=True, help='scratch directory for YAML, CSV and JSON')
    ap.add_argument('--stiffness', choices=['square', 'trapezoid', 'fourier'],
                    help='only the drawn cases with this true stiffness shape (same seeds)')
    ap.add_argument('--check', choices=['segments'] + sorted(CHECKS), action='append',
                    help='what to check against the truth (repeat for several on the same '
                    'runs; default: the piecewise segments)')
    ap.add_argument('--extras', action='store_true',
                    help='also draw torsional dynamics, substeps, speed ramps, trapezoid loads')
    ap.add_argument('--drop-mesh-phase', action='store_true',
                    help='analyse the records without their mesh_phase column (the switches then '
                    'held to the sample where the new value is first seen)')
    ap.add_argument('--torque-glitches', type=int, default=0, metavar='N',
                    help='add N one-sample glitches of 20-200 N*m to the torque column (a meter '
                    'or transmission spike the gear never felt) before the analysis')
    ap.add_argument('--torque-quantum', type=float, default=0.0, metavar='Q',
                    help='round the torque column to multiples of Q N*m (a quantiser without '
                    'dither) before the analysis')
    ap.add_argument('analyze_args', nargs='*', help='extra analyze options (after --)')
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    totals = dict.fromkeys(['cases', 'segments', 'not_identifiable', 'straddling', 'flagged',
                            'clean', 'wrong'], 0)
    checks = a.check or ['segments']
    counts = {ch: new_counts() for ch in checks}
    zs_of = {ch: {} for ch in checks}
    z_by_snr, by_shape = zs_of.get('segments', {}), {}
    for i in range(a.cases):
        seed = a.seed + i
        case = analyze_case(a, seed)
        if case is None:
            continue
        info, result, csv_name = case
        totals['cases'] += 1
        for ch in checks:
            if ch == 'segments':
                t, c = read_truth(csv_name)
                totals['_shape'] = info['stiffness']
                wrong = tally_case(result, t, c, info['damping'], info['snr'], totals,
                                   z_by_snr, by_shape)
            else:
                fn, names = CHECKS[ch]
                wrong = fn(result, read_truth(csv_name, names), info['snr'], counts[ch],
                           zs_of[ch])
            print(seed, ch, info, 'wrong', len(wrong), wrong[:3], flush=True)
    totals.pop('_shape', None)
    out = {}
    for ch in checks:
        # |z| > 4 happens to 6.3e-5 of calibrated normal errors: the noisy clean numbers' share.
        noisy = sum(len(zs) for snr, zs in zs_of[ch].items() if snr != '.inf')
        tot = totals if ch == 'segments' else dict(counts[ch], cases=totals['cases'])
        tot['wrong_expected_by_chance'] = round(6.3e-5 * noisy, 2)
        out[ch] = {'totals': tot, 'by_snr': coverage_of(zs_of[ch])}
        if ch == 'segments':
            out[ch]['by_true_stiffness'] = by_shape
    print(json.dumps(out if len(checks) > 1 else out[checks[0]], indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())

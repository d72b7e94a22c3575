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

Used for docs/method.md section 4 (Refinement: clean data) and docs/trust.md (integral_std).
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


def run(cmd):
    return subprocess.run(cmd, capture_output=True, text=True)


def simulate(bin_dir, name, text, info):
    """Writes NAME.yaml and NAME.csv; None when the simulator refuses the case."""
    for _ in range(2):
        with open(name + '.yaml', 'w') as f:
            f.write(text)
        p = run([os.path.join(bin_dir, 'simulate'), '-q', '--config', name + '.yaml',
                 '--output', name + '.csv'])
        if p.returncode == 0:
            return True
        if 'natural frequency' not in p.stderr:
            break
        text = text.replace(f"sample_rate: {info['rate']}", 'sample_rate: 1000000.0')
        info['rate'] = 1e6
    print('simulate refused', name, p.stderr.strip()[:200], file=sys.stderr)
    return False


def read_truth(path):
    """time and damping [N*s/m] columns of a simulated CSV."""
    t, c = [], []
    with open(path) as f:
        rows = csv.reader(f)
        head = next(rows)
        it, ic = head.index('time'), head.index('damping')
        for row in rows:
            t.append(float(row[it]))
            c.append(float(row[ic]))
    return t, c


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


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--bin-dir', required=True, help='directory holding simulate and analyze')
    ap.add_argument('--cases', type=int, default=100)
    ap.add_argument('--seed', type=int, default=1, help='first case seed (case i: seed + i)')
    ap.add_argument('--out', required=True, help='scratch directory for YAML, CSV and JSON')
    ap.add_argument('--stiffness', choices=['square', 'trapezoid', 'fourier'],
                    help='only the drawn cases with this true stiffness shape (same seeds)')
    ap.add_argument('analyze_args', nargs='*', help='extra analyze options (after --)')
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    totals = dict.fromkeys(['cases', 'segments', 'not_identifiable', 'straddling', 'flagged',
                            'clean', 'wrong'], 0)
    z_by_snr, by_shape = {}, {}
    for i in range(a.cases):
        seed = a.seed + i
        text, info = gear_yaml(random.Random(seed))
        if a.stiffness and info['stiffness'] != a.stiffness:
            continue
        name = os.path.join(a.out, f'case{seed}')
        if not simulate(a.bin_dir, name, text, info):
            continue
        p = run([os.path.join(a.bin_dir, 'analyze'), '-q', '--input', name + '.csv', '--params',
                 name + '.yaml', '--output', name + '.json'] + a.analyze_args)
        if p.returncode != 0:
            print('analyze failed', seed, p.returncode, p.stderr.strip()[:300])
            continue
        totals['cases'] += 1
        with open(name + '.json') as f:
            result = json.load(f)
        t, c = read_truth(name + '.csv')
        totals['_shape'] = info['stiffness']
        wrong = tally_case(result, t, c, info['damping'], info['snr'], totals, z_by_snr, by_shape)
        print(seed, info, 'wrong', len(wrong), wrong[:3], flush=True)
    coverage = {}
    for snr, zs in sorted(z_by_snr.items()):
        finite = [z for z in zs if math.isfinite(z)]
        coverage[snr] = {
            'clean': len(zs),
            'within_1.96_se': sum(abs(z) <= 1.96 for z in zs) / len(zs),
            'rms_z': math.sqrt(sum(z * z for z in finite) / len(finite)) if finite else None,
        }
    # |z| > 4 happens to 6.3e-5 of calibrated normal errors: the noisy clean segments' share.
    noisy = sum(len(zs) for snr, zs in z_by_snr.items() if snr != '.inf')
    totals['wrong_expected_by_chance'] = round(6.3e-5 * noisy, 2)
    totals.pop('_shape', None)
    print(json.dumps({'totals': totals, 'by_snr': coverage, 'by_true_stiffness': by_shape},
                     indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())

#!/usr/bin/env python3
"""Paper 004's NLLS-2L vs NLPT-2L claims over parameter draws x noise seeds (issue 34).

Runs both launch cases in-process (lockstep) for every (model.uncertainty_seed, seed) pair with
the same draw and seed for both, two runs at a time, and prints how often each claim holds:
  swing: NLLS-2L's rmse_load_vx and rmse_load_vy both below NLPT-2L's (paper: ratios 2.36, 1.47);
  psi:   NLPT/NLLS rmse_psi within 10 % of the paper's 0.99;
  iavu:  NLPT/NLLS iavu_f_r, f_l, tau_ar, tau_al each within 5 % of 1.004, 1.017, 0.998, 0.994.
Usage (from the repository root, after `cargo build --release`):
  python3 services/tiltrotor-gains/sweep.py --draws 1-20 --seeds 1-3 [--set KEY=VALUE ...] [--json out.json]
"""
import argparse, json, os, shutil, subprocess, sys, tempfile
from concurrent.futures import ThreadPoolExecutor

IAVU = [("iavu_f_r", 1.004), ("iavu_f_l", 1.017), ("iavu_tau_ar", 0.998), ("iavu_tau_al", 0.994)]


def span(text):
    lo, _, hi = text.partition("-")
    return range(int(lo), int(hi or lo) + 1)


def run(case, draw, seed, sets, root):
    out = os.path.join(root, f"{case}-{draw}-{seed}")
    cmd = ["./target/release/looplab", "run", f"launch/tiltrotor/{case}.toml", "--in-process", "-q", "--out", out,
           "--set", f"model.uncertainty_seed={draw}", "--set", f"seed={seed}"]
    for s in sets:
        cmd += ["--set", s]
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    path = os.path.join(out, "summary.json")
    metrics = None
    if done.returncode == 0 and os.path.exists(path):
        with open(path) as f:
            metrics = json.load(f)["metrics"]
    shutil.rmtree(out, ignore_errors=True)
    return metrics


def percentiles(xs):
    xs = sorted(xs)
    pick = lambda q: xs[min(len(xs) - 1, int(q * len(xs)))]
    return f"min {xs[0]:.2f}  p25 {pick(0.25):.2f}  median {pick(0.5):.2f}  p75 {pick(0.75):.2f}  max {xs[-1]:.2f}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", default="1-20")
    ap.add_argument("--seeds", default="1-3")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--json")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    pairs = [(d, s) for d in span(a.draws) for s in span(a.seeds)]
    root = tempfile.mkdtemp(prefix="tiltrotor-sweep-")
    jobs = [(c, d, s) for d, s in pairs for c in ("1-nlls-2l", "2-nlpt-2l")]
    with ThreadPoolExecutor(a.jobs) as pool:
        results = list(pool.map(lambda j: run(*j, a.set, root), jobs))
    shutil.rmtree(root, ignore_errors=True)
    rows, lost = [], []
    for i, (d, s) in enumerate(pairs):
        ls, pt = results[2 * i], results[2 * i + 1]
        if ls is None or pt is None or max(ls["position_error_max_m"], pt["position_error_max_m"]) > 2.0:
            lost.append(f"({d},{s}) {'NLLS' if ls is None or ls['position_error_max_m'] > 2.0 else ''}"
                        f"{'NLPT' if pt is None or pt['position_error_max_m'] > 2.0 else ''}")
            continue
        ratio = lambda k: pt[k] / ls[k]
        rows.append({"draw": d, "seed": s, "nlls": ls, "nlpt": pt,
                     "vx": ratio("rmse_load_vx_m_s"), "vy": ratio("rmse_load_vy_m_s"), "psi": ratio("rmse_psi_rad"),
                     "iavu": [ratio(k) for k, _ in IAVU]})
    n = len(pairs)
    print(f"lost (diverged, or beyond the 2 m limit): {len(lost)}/{n} {' '.join(lost)}")
    swing = [r for r in rows if r["vx"] > 1 and r["vy"] > 1]
    psi = [r for r in rows if abs(r["psi"] / 0.99 - 1) <= 0.10]
    iavu = [r for r in rows if all(abs(x / p - 1) <= 0.05 for x, (_, p) in zip(r["iavu"], IAVU))]
    print(f"pairs: {n} (draws {a.draws} x seeds {a.seeds}) {' '.join(a.set)}")
    print(f"swing lower with NLLS-2L in both axes: {len(swing)}/{n}")
    print(f"  NLPT/NLLS rmse_load_vx (paper 2.36): {percentiles([r['vx'] for r in rows])}")
    print(f"  NLPT/NLLS rmse_load_vy (paper 1.47): {percentiles([r['vy'] for r in rows])}")
    print(f"psi ratio within 10 % of 0.99: {len(psi)}/{n}   {percentiles([r['psi'] for r in rows])}")
    print(f"IAVU ratios all within 5 %: {len(iavu)}/{n}")
    for j, (k, p) in enumerate(IAVU):
        within = sum(abs(r['iavu'][j] / p - 1) <= 0.05 for r in rows)
        print(f"  {k} (paper {p}): {within}/{n} within 5 %   {percentiles([r['iavu'][j] for r in rows])}")
    failing = [f"({r['draw']},{r['seed']}) vx {r['vx']:.2f} vy {r['vy']:.2f}" for r in rows if r not in swing]
    print("swing fails:", "; ".join(failing) or "none")
    nlls_max_swing = max(r["nlls"]["load_swing_max_rad"] for r in rows)
    print(f"NLLS-2L worst load_swing_max_rad {nlls_max_swing:.3f}; worst position_error_max_m "
          f"{max(r['nlls']['position_error_max_m'] for r in rows):.3f} (NLPT {max(r['nlpt']['position_error_max_m'] for r in rows):.3f})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())

"""The simulator's KPIs recomputed from a run's saved trajectories, without the simulator's code.

    .venv/bin/python -m bench.kpi_recompute RUNS_DIR EVAL_CSV

RUNS_DIR is `sim evaluate --save-runs`' folder, EVAL_CSV that run's evaluation.csv. Written for
the simulator audit of 2026-12-04 as a second, independent reading of sim.kpi (the fuel model's
coefficients written out again, numpy and pandas only): each `_mine` row should equal its
`_csv` row. Beside them, the readings the audit asked about: fuel with the leader counted, fuel
per time, throughput without the cars that cut in (`tput_no_merged`), network speed with the
leader (docs/simulation.md, "What the verdict still leaves out").
"""

import argparse

import numpy as np
import pandas as pd

_arguments = argparse.ArgumentParser(description=__doc__.splitlines()[0])
_arguments.add_argument("runs_dir", help="the folder `sim evaluate --save-runs` wrote")
_arguments.add_argument("eval_csv", help="that run's evaluation.csv")
_given = _arguments.parse_args()
runs_dir, eval_csv = _given.runs_dir, _given.eval_csv
# RAV4_2019 coefficients (../shared/reference/energy-model.md), written out here
C = {
    "c0": 0.14631964767035743,
    "c1": 0.012179045946260292,
    "c2": 0.0,
    "c3": 2.7432588728174234e-05,
    "p0": 0.04553801347643801,
    "p1": 0.047436831067050676,
    "p2": 0.0018022443124799303,
    "q0": 0.0,
    "q1": 0.02609037187916979,
    "beta": 0.013111753095302022,
    "vc": 5.98,
}
GAL_PER_G = 1.268 / 3600
MILE = 1609.344


def fuel_gps(v, a):
    r = (
        C["c0"]
        + C["c1"] * v
        + C["c2"] * v**2
        + C["c3"] * v**3
        + (C["p0"] + C["p1"] * v + C["p2"] * v**2) * a
        + (C["q0"] + C["q1"] * v) * np.maximum(a, 0) ** 2
    )
    return np.maximum(r, np.where(v <= C["vc"], C["beta"], 0.0))


def load(f):
    d = pd.read_parquet(f"{runs_dir}/{f}")
    P = d.pivot(index="time_s", columns="vehicle", values="position_m").to_numpy()
    V = d.pivot(index="time_s", columns="vehicle", values="speed_mps").to_numpy()
    roles = d.drop_duplicates("vehicle").set_index("vehicle")["role"].sort_index()
    merged = np.isnan(P).any(axis=0)  # cars that merged in later
    return P, V, roles.to_numpy(), merged


def cross_times(P, dt, x):
    t = np.arange(P.shape[0]) * dt
    out = np.full(P.shape[1], np.nan)
    for j in range(P.shape[1]):
        ok = np.isfinite(P[:, j])
        p = P[ok, j]
        if ok.any() and p[0] <= x <= p[-1]:
            out[j] = np.interp(x, p, t[ok])
    return out


def tput(P, own, dt, pts, count_merged=True):
    vals = []
    for x in pts:
        tt = cross_times(P, dt, x)
        n = np.isfinite(tt[own]).sum() + (np.isfinite(tt[~own]).sum() if count_merged else 0)
        spread = np.nanmax(tt[own]) - np.nanmin(tt[own])
        vals.append((n - 1) / spread * 3600)
    return np.mean(vals)


def kpis(P, V, own, dt, with_leader=False):
    cols = np.flatnonzero(own)
    if not with_leader:
        cols = cols[1:]
    p, v = P[:, cols], V[:, cols]
    a = np.diff(v, axis=0) / dt
    fuel = fuel_gps(v[:-1], a).sum() * dt
    dist = (p[-1] - p[0]).sum()
    mpg = dist / MILE / (fuel * GAL_PER_G)
    per_time_gps = fuel / (dt * (p.shape[0] - 1) * p.shape[1])
    netspeed = dist / ((p.shape[0] - 1) * dt * p.shape[1])
    return mpg, per_time_gps, netspeed, dist


idx = pd.read_csv(f"{runs_dir}/runs.csv")
ev = pd.read_csv(eval_csv)
dt = 0.1
rows = []
for (scen, drive), g in idx.groupby(["scenario", "drive"], sort=False):
    base = g[g.controller == "baseline"].iloc[0]
    Pb, Vb, rb, mb = load(base.file)
    ownb = ~mb
    for _, r in g[g.controller != "baseline"].iterrows():
        P, V, roles, m = load(r.file)
        own = ~m
        # shared stretch: every own vehicle of both runs (leader included)
        first = max(Pb[0, ownb].max(), P[0, own].max())
        last = min(Pb[-1, ownb].min(), P[-1, own].min())
        pts = np.linspace(first, last, 7)[1:-1]
        mpg_b, gps_b, ns_b, d_b = kpis(Pb, Vb, ownb, dt)
        mpg, gps, ns, d = kpis(P, V, own, dt)
        mpgL_b, _, nsL_b, _ = kpis(Pb, Vb, ownb, dt, True)
        mpgL, _, nsL, _ = kpis(P, V, own, dt, True)
        tb, t = tput(Pb, ownb, dt, pts), tput(P, own, dt, pts)
        tb0, t0 = tput(Pb, ownb, dt, pts, False), tput(P, own, dt, pts, False)
        # AV gap envelope (to whatever car is directly ahead, merged cars included)
        av = np.flatnonzero(roles == "av")[0]
        ahead = P - P[:, [av]]
        ahead[:, av] = np.nan
        ahead[~(ahead > 0)] = np.inf
        gap = ahead.min(axis=1) - 5.0
        vav = V[:, av]
        outside = (gap < 7) | (gap > 120) | ((vav >= 1) & (gap < 1.0 * vav))
        # collisions: any follower whose gap to the car directly ahead reached 0
        coll = 0
        for j in range(1, P.shape[1]):
            a_ = P - P[:, [j]]
            a_[:, j] = np.nan
            a_[~(a_ > 0)] = np.inf
            gj = a_.min(axis=1) - 5.0
            gj = gj[np.isfinite(P[:, j]) & np.isfinite(gj)]
            coll += int((gj <= 0).any())
        e = ev[(ev.scenario == scen) & (ev.drive == drive) & (ev.controller == r.controller)].iloc[
            0
        ]
        rows.append(
            {
                "scen": scen,
                "drive": drive[:19],
                "ctrl": r.controller[:22],
                "fuel_mine": 100 * (1 - mpg_b / mpg),
                "fuel_csv": e.fuel_saving_pct,
                "fuel_with_leader": 100 * (1 - mpgL_b / mpgL),
                "fuel_per_time": 100 * (1 - gps / gps_b),
                "tput_mine": 100 * (t / tb - 1),
                "tput_csv": e.throughput_change_pct,
                "tput_no_merged": 100 * (t0 / tb0 - 1),
                "ns_mine": 100 * (ns / ns_b - 1),
                "ns_csv": e.network_speed_change_pct,
                "ns_with_leader": 100 * (nsL / nsL_b - 1),
                "within_mine": 1 - outside.mean(),
                "within_csv": e.within_bounds_share,
                "coll_mine": coll,
                "coll_csv": e.collisions,
                "cutins": int(m.sum()),
                "cutins_base": int(mb.sum()),
                "lost_mine": Pb[-1, av] - P[-1, av],
                "lost_csv": e.distance_lost_m,
            }
        )
pd.set_option("display.width", 250)
pd.set_option("display.max_columns", 40)
print(pd.DataFrame(rows).round(3).T)

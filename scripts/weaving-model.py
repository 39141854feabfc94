#!/usr/bin/env python3
"""An offline model of the weaving pipeline, to measure what a better lateral estimate would buy
before building it in KPL (docs/situations.md#weaving).

For every vehicle of each seed it takes the true trajectory that a run recorded (`tracker.truth`
in `sumo_weaving/tracks.jsonl`), adds the simulated tracker's noise to the lateral position and
velocity, estimates the lateral position with a one-dimensional constant-velocity Kalman filter
(position and velocity measured, as `anchor.kalman` does on each axis), optionally refined by a
fixed-lag Rauch-Tung-Striebel smoother (`--lag`) or averaged over a trailing window
(`--moving-average`), and runs the weaving chronicle of specs/traffic/sumo_weaving.kpl on the
estimate's distance from the nearest lane centre: a hysteresis (out above 1.3 m, back below 0.5 m),
three departures and returns each at least 1 s apart, within 30 s, overlapping recognitions of one
vehicle merged. Recognitions are scored against the seed's truth.jsonl per situation (a
recognition is correct when it overlaps a true situation of the same vehicle), as `kpl situations`
scores them.

It is a model, not KPL: no missed detections, false positives or association, and the chronicle
as a direct search. On the shipped filter it gives precision and recall about 0.04 above what
the full pipeline gets on the same seeds, so compare its variants with each other, not with
`kpl situations`.

    scripts/weaving-model.py --dir DIR --seeds 42,1,2 --lag 2.0

DIR/sN/sumo/weaving/truth.jsonl (scripts/sumo-scenarios.py --only weaving --seed N --out DIR/sN/sumo)
and DIR/sN/out/sumo_weaving/tracks.jsonl (kpl run of the spec copied to DIR/sN) for each seed N.
Needs numpy.
"""
import argparse
import json
import os

import numpy as np

LANE_CENTRES = np.array([-1.6, -4.8])  # the weaving road's two lanes (y, metres)
ENTER_M, LEAVE_M, MIN_GAP_S, WINDOW_S = 1.3, 0.5, 1.0, 30.0
SETTLE_S = 1.5  # what the links take before a car exists (establish 500 ms twice, plus on_road)


def trajectories(path):
    """vehicle -> [(time s, y, lateral velocity)] while visible, from a run's tracker.truth."""
    out = {}
    with open(path) as f:
        for line in f:
            sample = json.loads(line)
            if "truth" not in sample["stream"]:
                continue
            for v in sample["value"]:
                if v["visible"]:
                    out.setdefault(v["id"], []).append((sample["valid"] / 1e6, v["pos"][1], v["vel"][1]))
    return out


def estimate(t, z, zv, args):
    """The filtered lateral position at each time, smoothed with a fixed lag if asked."""
    n = len(t)
    r, rv = args.noise ** 2, args.velocity_noise ** 2
    xs, ps, xp, pp = np.zeros((n, 2)), np.zeros((n, 2, 2)), np.zeros((n, 2)), np.zeros((n, 2, 2))
    x, p = np.array([z[0], zv[0]]), np.diag([r, rv])
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            f = np.array([[1.0, dt], [0.0, 1.0]])
            q = args.acceleration_noise * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
            x, p = f @ x, f @ p @ f.T + q
        xp[k], pp[k] = x, p
        gain = p @ np.linalg.inv(p + np.diag([r, rv]))
        x, p = x + gain @ (np.array([z[k], zv[k]]) - x), (np.eye(2) - gain) @ p
        xs[k], ps[k] = x, p
    lag = int(round(args.lag * 10))
    if lag == 0:
        out = xs[:, 0]
    else:
        out = np.zeros(n)
        for k in range(n):
            end = min(n - 1, k + lag)
            smoothed = xs[end]
            for j in range(end - 1, k - 1, -1):
                f = np.array([[1.0, t[j + 1] - t[j]], [0.0, 1.0]])
                c = ps[j] @ f.T @ np.linalg.inv(pp[j + 1])
                smoothed = xs[j] + c @ (smoothed - xp[j + 1])
            out[k] = smoothed[0]
    width = int(round(args.moving_average * 10))
    if width > 1:
        sums = np.cumsum(np.insert(out, 0, 0.0))
        starts = np.maximum(0, np.arange(n) - width + 1)
        out = (sums[1:] - sums[starts]) / (np.arange(n) + 1 - starts)
    return out


def recognise(t, offset):
    """The chronicle's recognitions, [first departure, last return], merged per vehicle."""
    outs, backs, out = [], [], False
    for time, o in zip(t, offset):
        if not out and o > ENTER_M:
            out = True
            outs.append(time)
        elif out and o < LEAVE_M:
            out = False
            backs.append(time)

    def chain(first, previous, departure, left):
        if left == 0:
            return previous
        for time in outs if departure else backs:
            if MIN_GAP_S <= time - previous <= WINDOW_S and time - first <= WINDOW_S:
                end = chain(first, time, not departure, left - 1)
                if end is not None:
                    return end
        return None

    found = sorted([first, end] for first in outs if (end := chain(first, first, False, 5)) is not None)
    merged = []
    for start, end in found:
        if merged and start <= merged[-1][1]:
            merged[-1][1] = max(end, merged[-1][1])
        else:
            merged.append([start, end])
    return merged


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dir", required=True)
    parser.add_argument("--seeds", default="42," + ",".join(str(s) for s in range(1, 27)))
    parser.add_argument("--noise", type=float, default=1.0, help="tracker position noise, m per axis")
    parser.add_argument("--velocity-noise", type=float, default=0.5, help="tracker velocity noise, m/s per axis")
    parser.add_argument("--acceleration-noise", type=float, default=2.0, help="the filter's q, m^2/s^3")
    parser.add_argument("--lag", type=float, default=0.0, help="fixed-lag smoother's lag, s (0: the filter)")
    parser.add_argument("--moving-average", type=float, default=0.0, help="trailing average, s")
    parser.add_argument("--rng-seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.rng_seed)
    recognised = correct = true = found = 0
    for seed in args.seeds.split(","):
        folder = os.path.join(args.dir, "s" + seed)
        with open(os.path.join(folder, "sumo", "weaving", "truth.jsonl")) as f:
            truth = [x for x in map(json.loads, f) if x["kind"] == "weaving"]
        for vehicle, series in trajectories(os.path.join(folder, "out", "sumo_weaving", "tracks.jsonl")).items():
            a = np.array(series)
            if len(a) < 30:
                continue
            t, y, vy = a[:, 0], a[:, 1], a[:, 2]
            z, zv = y + rng.normal(0, args.noise, len(y)), vy + rng.normal(0, args.velocity_noise, len(y))
            est = estimate(t, z, zv, args)
            offset = np.min(np.abs(est[:, None] - LANE_CENTRES[None, :]), axis=1)
            keep = t - t[0] >= SETTLE_S
            recs = recognise(t[keep], offset[keep])
            spans = [(x["start"], x["end"]) for x in truth if x["objects"][0] == vehicle]
            recognised += len(recs)
            correct += sum(any(a < e and b > s for s, e in spans) for a, b in recs)
            true += len(spans)
            found += sum(any(a < e and b > s for a, b in recs) for s, e in spans)
    print(json.dumps({"recognised": recognised, "correct": correct, "truth": true, "found": found,
                      "precision": round(correct / max(recognised, 1), 3), "recall": round(found / max(true, 1), 3)}))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Yaw-bias error before and after each geolocation restart of a `dualgeo run` on the
live simulator (issue #13: "bias error after the restart no worse than before it").

Usage: scripts/bias_across_restarts.py OUT_DIR RUN_LOG [WINDOW_S [CONTROL_OUT_DIR]]

OUT_DIR is the run's --out (track.csv, stream/telemetry.csv, stream/truth.csv);
RUN_LOG its stderr, where each restarted geolocation logs `resumed from the checkpoint
... t_s=T` (T: the last estimate before the restart). For each restart it prints the
mean |yaw-bias error| of both UAVs over the WINDOW_S (default 2 s) of estimates before
T and after it; with CONTROL_OUT_DIR (a run of the same scenario without kills) also the
same windows there. Evaluation only: truth is read here, never by the pipeline.
"""
import csv
import re
import sys
from bisect import bisect_left


def wrap(d):
    return (d + 180.0) % 360.0 - 180.0


def errors(out):
    """err(lo, hi): mean |yaw-bias error| of the estimates of `out` in (lo, hi]."""
    tele = list(csv.DictReader(open(f"{out}/stream/telemetry.csv")))
    truth = list(csv.DictReader(open(f"{out}/stream/truth.csv")))
    bias = {"left": [], "right": []}
    for m, t in zip(tele, truth):
        bias[m["uav"]].append((float(m["t_s"]), wrap(float(m["yaw_deg"]) - float(t["yaw_deg"]))))
    for k in bias:
        bias[k].sort()
    times = {k: [t for t, _ in v] for k, v in bias.items()}

    def true_bias(uav, t):
        i = bisect_left(times[uav], t - 1e-6)
        i = min(i, len(times[uav]) - 1)
        return bias[uav][i][1]

    track = [
        (float(r["t_s"]), float(r["yaw_bias_left_deg"]), float(r["yaw_bias_right_deg"]))
        for r in csv.DictReader(open(f"{out}/track.csv"))
    ]

    def err(lo, hi):
        e = [
            (abs(wrap(l - true_bias("left", t))) + abs(wrap(r - true_bias("right", t)))) / 2
            for t, l, r in track
            if lo < t <= hi
        ]
        return (sum(e) / len(e) if e else float("nan")), len(e)

    return err


def main():
    out, log = sys.argv[1], sys.argv[2]
    window = float(sys.argv[3]) if len(sys.argv) > 3 else 2.0
    control = errors(sys.argv[4]) if len(sys.argv) > 4 else None
    err = errors(out)
    text = re.sub(r"\x1b\[[0-9;]*m", "", open(log).read())
    resumes = [float(t) for t in re.findall(r"resumed from the checkpoint.*?t_s=([0-9.]+)", text)]
    print("restart at t_s | mean |bias error| (°): before  after | control before  after")
    for t0 in resumes:
        (b, nb), (a, na) = err(t0 - window, t0), err(t0, t0 + window)
        line = f"{t0:14.2f} | {b:21.2f} {a:6.2f} ({nb}, {na})"
        if control:
            (cb, _), (ca, _) = control(t0 - window, t0), control(t0, t0 + window)
            line += f" | {cb:14.2f} {ca:6.2f}"
        print(line)


if __name__ == "__main__":
    main()

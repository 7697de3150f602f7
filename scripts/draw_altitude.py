#!/usr/bin/env python3
"""What a simulated flight's navigation-noise draw says about the target's altitude, with
no filter in between (issue #23: is an altitude excursion the filter's or the draw's?).

Usage: scripts/draw_altitude.py RECORDING [FROM_S [EVERY]]

RECORDING is a `dualgeo simulate` output (telemetry.csv, truth.csv). For every EVERY-th
stereo pair (default 2, the Monte Carlo's; frames 1, 3, 5, ... as it takes them) from
FROM_S (default 0: the filter's first estimate is the useful start) it takes the exact
rays to the target (truth's pixels, no detection or matching error), turns them by the
draw's attitude error (the measured attitude with the yaw bias removed: the bias is a
line fitted to each UAV's yaw error, eq. (34)'s form), starts them at the measured
positions, and meets them in least squares. It prints the pairs' altitude error: per
second, then the running mean since FROM_S against its standard error (the spread of all
pairs over the recording / sqrt(n)). A filter that takes only those pairs, with their
true spread, would be as many standard errors off as the last column says; an excursion
the filter shares with it is in the draw, not the filter.

Evaluation only: truth is read here, never by the pipeline. Plain Python (no numpy).
"""
import csv
import math
import sys


def wrap(d):
    return (d + 180.0) % 360.0 - 180.0


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def apply(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def transpose(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


def camera_axes(yaw_deg, pitch_deg, roll_deg):
    """Body (FRD) to world (ENU): C_enu^ned Rz(yaw) Ry(pitch) Rx(roll), as
    shared_types::conventions::body_to_ned. The camera mount cancels out: the same
    body-frame ray is turned by the true and by the measured attitude."""
    y, p, r = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    rz = [[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]]
    ry = [[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]]
    rx = [[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]]
    ned_to_enu = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]
    return matmul(ned_to_enu, matmul(rz, matmul(ry, rx)))


def solve3(a, b):
    """a x = b by Cramer's rule (a is symmetric positive definite here)."""
    def det(m):
        return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    d = det(a)
    out = []
    for c in range(3):
        m = [row[:] for row in a]
        for i in range(3):
            m[i][c] = b[i]
        out.append(det(m) / d)
    return out


def fit_line(ts, ys):
    n = len(ts)
    mt, my = sum(ts) / n, sum(ys) / n
    stt = sum((t - mt) ** 2 for t in ts)
    slope = sum((t - mt) * (y - my) for t, y in zip(ts, ys)) / stt if stt > 0 else 0.0
    return lambda t: my + slope * (t - mt)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    rec = sys.argv[1]
    from_s = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    every = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    key = lambda r: (r["uav"], int(r["frame"]))
    tel = {key(r): r for r in csv.DictReader(open(f"{rec}/telemetry.csv"))}
    tru = {key(r): r for r in csv.DictReader(open(f"{rec}/truth.csv"))}
    frames = sorted({f for (_, f) in tru if ("left", f) in tel and ("right", f) in tel})
    if not frames:
        sys.exit(f"{rec}: no frame in both telemetry.csv and truth.csv")
    bias = {}
    for uav in ("left", "right"):
        ts = [float(tru[(uav, f)]["t_s"]) for f in frames]
        ys = [wrap(float(tel[(uav, f)]["yaw_deg"]) - float(tru[(uav, f)]["yaw_deg"])) for f in frames]
        bias[uav] = fit_line(ts, ys)
    pairs = []
    for f in frames:
        a_sum = [[0.0] * 3 for _ in range(3)]
        b_sum = [0.0] * 3
        for uav in ("left", "right"):
            m, t = tel[(uav, f)], tru[(uav, f)]
            cam = [float(t[k]) for k in ("x_m", "y_m", "z_m")]
            target = [float(t[k]) for k in ("target_x_m", "target_y_m", "target_z_m")]
            true_axes = camera_axes(*(float(t[k]) for k in ("yaw_deg", "pitch_deg", "roll_deg")))
            body = apply(transpose(true_axes), [target[i] - cam[i] for i in range(3)])
            t_s = float(t["t_s"])
            measured = camera_axes(
                float(m["yaw_deg"]) - bias[uav](t_s), float(m["pitch_deg"]), float(m["roll_deg"])
            )
            d = apply(measured, body)
            norm = math.sqrt(sum(v * v for v in d))
            d = [v / norm for v in d]
            p = [float(m[k]) for k in ("x_m", "y_m", "z_m")]
            proj = [[(i == j) - d[i] * d[j] for j in range(3)] for i in range(3)]
            for i in range(3):
                b_sum[i] += sum(proj[i][j] * p[j] for j in range(3))
                for j in range(3):
                    a_sum[i][j] += proj[i][j]
        meet = solve3(a_sum, b_sum)
        pairs.append((f, t_s, meet[2] - target[2]))
    spread = math.sqrt(sum(z * z for (_, _, z) in pairs) / len(pairs))
    taken = [(t, z) for (f, t, z) in pairs if f % every == 1 % every and t >= from_s - 1e-9]
    print(f"{rec}: {len(pairs)} pairs, altitude error spread {spread:.2f} m per pair; "
          f"bias lines removed: left {bias['left'](0):+.2f}°, right {bias['right'](0):+.2f}° at 0 s")
    print(f"every {every}. pair from {from_s:g} s: {len(taken)} pairs")
    print("second | pairs | mean z err (m) | running mean since start (m) | standard error (m) | ratio")
    running = []
    for second in range(int(from_s), int(math.ceil(taken[-1][0])) + 1 if taken else 0):
        these = [z for (t, z) in taken if second <= t < second + 1]
        if not these:
            continue
        running += these
        mean = sum(these) / len(these)
        run_mean = sum(running) / len(running)
        se = spread / math.sqrt(len(running))
        print(f"{second:6d} | {len(these):5d} | {mean:+14.2f} | {run_mean:+28.2f} | "
              f"{se:18.2f} | {run_mean / se:+5.1f}")


if __name__ == "__main__":
    main()

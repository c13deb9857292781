"""Gathers the cells of scripts/compare_controllers.sh into OUT/controllers.csv and OUT/pairs.csv.

usage: compare_controllers_gather.py WORK OUT

WORK/CELL/SET/ holds one `flatland montecarlo --out` (runs.csv, result.json) per set of
controllers run together on CELL's worlds (WORK/CELL/scene.yaml: the loop's scene). Each
controller's row comes from its result.json summary; the pairs are counted over the worlds
(runs.csv, matched by run) that both controllers ran without a numerical failure, with the exact
two-sided McNemar p-value. For a pair run in one set, montecarlo's own "pairs" must agree, which
is checked (an AssertionError otherwise)."""

import csv
import json
import math
import os
import sys


def mcnemar(only_a, only_b):
    """Exact two-sided McNemar: min(1, 2 P[Binomial(d, 1/2) <= min(only_a, only_b)]), d the
    discordant worlds (drivers::mcnemar_exact_p)."""
    d = only_a + only_b
    if d == 0:
        return 1.0
    return min(1.0, 2 * sum(math.comb(d, i) for i in range(min(only_a, only_b) + 1)) / 2**d)


def controller_row(common, summary):
    counted = summary["runs"] - summary["numerical_failures"] - summary.get("invalid_worlds", 0)
    failures = {k: v for k, v in summary["outcomes"].items()
                if k not in ("success", "invalid_world") and v}
    return {**common, "controller": summary["controller"], "successes": summary["successes"],
            "counted": counted,
            "success_rate": summary["successes"] / counted if counted else float("nan"),
            "ci95_lo": summary["ci95"][0], "ci95_hi": summary["ci95"][1],
            "failures": " ".join(f"{k}:{v}" for k, v in sorted(failures.items())),
            "safe_stops": " ".join(f"{k}:{v}" for k, v in sorted(summary["safe_stops"].items())),
            "duration_median_s": summary["duration_s"]["median"],
            "fn_min_ratio_median": summary["fn_min_ratio"]["median"],
            "fn_min_ratio_p05": summary["fn_min_ratio"]["p05"],
            "fn_min_ratio_min": summary["fn_min_ratio"]["min"],
            "friction_use_median": summary["friction_use"]["median"],
            "friction_use_p95": summary["friction_use"]["p95"],
            "friction_use_max": summary["friction_use"]["max"]}


def gather_cell(work, cell, rows, pairs):
    cell_dir = os.path.join(work, cell)
    sets = sorted(s for s in os.listdir(cell_dir)
                  if os.path.isfile(os.path.join(cell_dir, s, "result.json")))
    if not sets:
        return
    with open(os.path.join(cell_dir, "scene.yaml")) as f:
        fps = next(float(line.split()[1]) for line in f if line.startswith("  fps: "))
    success, names, tool_pairs, runs, common = {}, [], {}, None, None
    for s in sets:
        with open(os.path.join(cell_dir, s, "result.json")) as f:
            r = json.load(f)
        assert runs in (None, r["runs"]), f"{cell}: sets of different sizes"
        runs, p = r["runs"], r["perturbations"]
        common = {"cell": cell, "rate_hz": fps, "latency_s": p["latency"],
                  "latency_frames": round(p["latency"] * fps, 2), "tilt_deg": p["tilt_deg"],
                  "contact_rel": p["contact_rel"], "s_h": p["s_h"], "runs": r["runs"]}
        for q in r["pairs"]:
            tool_pairs[(q["a"], q["b"])] = q
        for summary in r["summaries"]:
            assert summary["controller"] not in names, f"{cell}: {summary['controller']} twice"
            names.append(summary["controller"])
            rows.append(controller_row(common, summary))
        with open(os.path.join(cell_dir, s, "runs.csv"), newline="") as f:
            for rec in csv.DictReader(f):
                ok = (None if rec["outcome"] in ("numerical_failure", "invalid_world")
                      else rec["success"] == "1")
                success[(rec["controller"], int(rec["run"]))] = ok
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            n = {"worlds": 0, "both": 0, "only_a": 0, "only_b": 0, "neither": 0}
            for w in range(runs):
                x, y = success[(a, w)], success[(b, w)]
                if x is None or y is None:
                    continue
                n["worlds"] += 1
                n["both" if x and y else "only_a" if x else "only_b" if y else "neither"] += 1
            pair = {**common, "a": a, "b": b, **n, "p_value": mcnemar(n["only_a"], n["only_b"])}
            pairs.append(pair)
            if (a, b) in tool_pairs:  # run together: montecarlo's own comparison must agree
                t = tool_pairs[(a, b)]
                assert all(t[k] == n[k] for k in n), (cell, a, b, t, n)
                assert abs(t["p_value"] - pair["p_value"]) <= 1e-12 * max(1.0, t["p_value"]), t


def write(path, table):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]), lineterminator="\n")
        w.writeheader()
        for row in table:
            w.writerow({k: ("nan" if v is None else v) for k, v in row.items()})


def plot_rows(rows):
    """The plot's series, each contiguous (gnuplot joins consecutive points only): per
    perturbation its half-width over the default (the headline cell is 1), per camera rate the
    latency in frames; success and its interval in %."""
    default = {"tilt": ("tilt_deg", 0.25), "contact": ("contact_rel", 0.2), "start": ("s_h", 0.02)}
    series = []
    for name, (column, base) in default.items():
        for r in rows:
            if r["cell"] == "headline" or r["cell"].startswith(name + "-"):
                series.append((name, r["controller"], r[column] / base, r))
    for r in rows:
        if r["cell"] == "headline" or r["cell"].startswith("camera-"):
            series.append((f"camera-{r['rate_hz']:g}", r["controller"], r["latency_frames"], r))
    series.sort(key=lambda t: (t[0], t[1], t[2]))
    return [{"series": name, "controller": c, "x": x, "success_pct": 100 * r["success_rate"],
             "ci95_lo_pct": 100 * r["ci95_lo"], "ci95_hi_pct": 100 * r["ci95_hi"]}
            for name, c, x, r in series]


def main():
    if len(sys.argv) != 3:
        print("usage: compare_controllers_gather.py WORK OUT", file=sys.stderr)
        sys.exit(2)
    work, out = sys.argv[1], sys.argv[2]
    rows, pairs = [], []
    for cell in sorted(os.listdir(work)):
        if os.path.isdir(os.path.join(work, cell)):
            gather_cell(work, cell, rows, pairs)
    if not rows:
        print(f"compare_controllers_gather.py: no cells in {work}", file=sys.stderr)
        sys.exit(2)
    write(os.path.join(out, "controllers.csv"), rows)
    write(os.path.join(out, "controllers_plot.csv"), plot_rows(rows))
    if pairs:
        write(os.path.join(out, "pairs.csv"), pairs)
    print(f"{len(rows)} cell x controller rows, {len(pairs)} pairs", file=sys.stderr)


if __name__ == "__main__":
    main()

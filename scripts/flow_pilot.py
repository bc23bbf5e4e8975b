#!/usr/bin/env python3
"""The flow pilot's table and curves (scripts/flow_pilot.sh): for each fine-tune under
OUT/finetune, its held-out flow figures against zero flow, and its held-out AEPE every
--eval-every steps from its log.jsonl. Writes OUT/pilot.md, OUT/curves.json and OUT/curves.svg
(held-out AEPE over zero flow's against steps; RUNS, a comma-separated list of substrings,
picks the runs plotted). Runs that differ only in their initialisation and seed (a name ending in
-seedN; none is seed 0) are paired seed by seed: pilot.md gives each pair of initialisations'
mean AEPE difference over the seeds both have, its 95 % t-interval, and the half-width as a share
of the difference (the fine-tuning table's criterion asks for at most a quarter).

    scripts/flow_pilot.py OUT [RUNS] [--max-ratio INIT=RATIO [--check-runs NAMES]]

--max-ratio makes it a test (tests/learning/flow_learns.sh): exit status 1, naming the run, when a
finished fine-tune from INIT ends with held-out AEPE above RATIO times zero flow's, or when no
fine-tune from INIT has finished. --check-runs (a comma-separated list of run names, as
flow_pilot.sh passes the runs it was asked for) checks those runs alone, each of which must have
finished, so that other runs kept in OUT do not count.
"""

import argparse
import json
import math
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from finetune_table import interval  # noqa: E402

INIT_ORDER = ["random", "mae", "croco"]
NAME = re.compile(r"^(?P<head>.+?-scale\d+)-(?P<init>[a-z]+)-(?P<tail>s\d+-.+?)"
                  r"(?:-seed(?P<seed>\d+))?$")


def curve(run):
    """[(steps done, held-out AEPE)] from a fine-tune's log.jsonl."""
    points = []
    for line in (run / "log.jsonl").read_text().splitlines():
        entry = json.loads(line)
        if "heldout" in entry:
            points.append((entry["step"] + 1, entry["heldout"]["aepe"]))
    return points


def paired(aepe):
    """Lines of the paired table from {run name: AEPE}: for each configuration (the name less its
    initialisation and seed) and each two of its initialisations, the later one's gain over the
    earlier (earlier minus later, px) over the seeds both have, when there are two or more."""
    runs = {}
    for name, value in aepe.items():
        m = NAME.match(name)
        if m and m["init"] in INIT_ORDER:
            config = f"{m['head']}-{m['tail']}"
            runs.setdefault(config, {}).setdefault(m["init"], {})[int(m["seed"] or 0)] = value
    lines = []
    for config, inits in sorted(runs.items()):
        names = [i for i in INIT_ORDER if i in inits]
        for a, b in [(a, b) for k, a in enumerate(names) for b in names[k + 1:]]:
            seeds = sorted(set(inits[a]) & set(inits[b]))
            if len(seeds) < 2:
                continue
            mean, half = interval([inits[a][s] - inits[b][s] for s in seeds])
            share = f"{half / abs(mean):.2f}" if mean else "inf"
            lines.append(f"| {config} | {a} - {b} | {len(seeds)} | {mean:.3f} ± {half:.3f} "
                         f"| {share} |")
    if not lines:
        return []
    return ["", "Paired over seeds: AEPE difference (px), the first initialisation's minus the "
            "second's (positive: the second is better), with its 95 % t-interval:", "",
            "| configuration | pair | seeds | difference | half-width / difference |",
            "| --- | --- | --- | --- | --- |"] + lines


COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf", "#393b79", "#ad494a"]


def svg_plot(curves, zero, path):
    """A line per run: held-out AEPE / zero flow's against steps done, and the line y = 1."""
    width, height, left, right, top, bottom = 640, 360, 60, 190, 20, 40
    xs = [x for points in curves.values() for x, _ in points] or [1]
    ys = [y / zero for points in curves.values() for _, y in points] + [1.0]
    x_max, y_lo, y_hi = max(xs), min(ys) - 0.01, max(ys) + 0.01
    px = lambda x: left + (width - left - right) * x / x_max
    py = lambda y: top + (height - top - bottom) * (y_hi - y) / (y_hi - y_lo)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="sans-serif" font-size="11">',
           f'<rect width="{width}" height="{height}" fill="white"/>',
           f'<line x1="{left}" y1="{py(1):.1f}" x2="{width - right}" y2="{py(1):.1f}" '
           f'stroke="black" stroke-dasharray="4 3"/>',
           f'<text x="{width - right + 4}" y="{py(1) + 4:.1f}">zero flow</text>',
           f'<line x1="{left}" y1="{height - bottom}" x2="{width - right}" y2="{height - bottom}" '
           f'stroke="black"/>',
           f'<line x1="{left}" y1="{top}" x2="{left}" y2="{height - bottom}" stroke="black"/>',
           f'<text x="{(left + width - right) / 2}" y="{height - 8}" text-anchor="middle">'
           f'fine-tuning steps</text>',
           f'<text x="14" y="{(top + height - bottom) / 2}" text-anchor="middle" '
           f'transform="rotate(-90 14 {(top + height - bottom) / 2})">held-out AEPE / zero flow'
           f'</text>']
    for k in range(5):
        y = y_lo + (y_hi - y_lo) * k / 4
        out.append(f'<text x="{left - 4}" y="{py(y) + 4:.1f}" text-anchor="end">{y:.3f}</text>')
        x = x_max * k / 4
        out.append(f'<text x="{px(x):.1f}" y="{height - bottom + 14}" text-anchor="middle">'
                   f'{x:.0f}</text>')
    for i, (name, points) in enumerate(sorted(curves.items())):
        colour = COLOURS[i % len(COLOURS)]
        line = " ".join(f"{px(x):.1f},{py(y / zero):.1f}" for x, y in points)
        out.append(f'<polyline points="{line}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        out.append(f'<text x="{width - right + 4}" y="{top + 14 * (i + 2)}" fill="{colour}">'
                   f'{name}</text>')
    out.append("</svg>")
    path.write_text("\n".join(out) + "\n")


def over_ratio(rows, init, most, names=None):
    """The failures of --max-ratio INIT=MOST among the table's rows (those named in `names`, when
    given, each of which must be there), one line each."""
    is_init = lambda name: (m := NAME.match(name)) is not None and m["init"] == init
    finished = {r[0] for r in rows}
    missing = [n for n in names or [] if is_init(n) and n not in finished]
    mine = [r for r in rows if is_init(r[0]) and (names is None or r[0] in names)]
    if missing:
        return [f"flow_pilot: {n}: not finished (no heldout.json)" for n in missing]
    if not mine:
        return [f"flow_pilot: no finished fine-tune from {init}"]
    return [f"flow_pilot: {r[0]}: held-out AEPE {r[1]:.3f} px is {r[3]:.3f} of zero flow's "
            f"{r[2]:.3f}, above {most}" for r in mine if r[3] > most]


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("runs", nargs="?", help="comma-separated substrings of the runs plotted")
    parser.add_argument("--max-ratio", metavar="INIT=RATIO")
    parser.add_argument("--check-runs", metavar="NAMES")
    args = parser.parse_args()
    if args.check_runs is not None and not args.max_ratio:
        parser.error("--check-runs needs --max-ratio")
    args.check_runs = args.check_runs.split(",") if args.check_runs else None
    if args.max_ratio:
        init, _, ratio = args.max_ratio.partition("=")
        try:
            value = float(ratio)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or value <= 0:
            parser.error(f"--max-ratio wants INIT=RATIO with RATIO > 0, not '{args.max_ratio}'")
        args.max_ratio = (init, value)
        if init not in INIT_ORDER:
            parser.error(f"--max-ratio: unknown initialisation '{init}' (one of {INIT_ORDER})")
    return args


def main():
    args = parse_args()
    out = args.out
    if not (out / "finetune").is_dir():
        print(f"flow_pilot: {out / 'finetune'}: no such folder", file=sys.stderr)
        return 1
    rows, curves, zero = [], {}, None
    for run in sorted((out / "finetune").iterdir()):
        heldout = run / "heldout.json"
        if not heldout.exists():
            continue
        report = json.loads(heldout.read_text())
        model, baseline = report["model"], report["baseline"]
        zero = baseline["aepe"]
        summary = json.loads((run / "summary.json").read_text())
        rows.append((run.name, model["aepe"], zero, model["aepe"] / zero,
                     model["aepe_covisible"], model["aepe_all_known"], model["px3"],
                     summary.get("seconds", float("nan"))))
        curves[run.name] = curve(run)
    lines = ["| run (patch, flow scale, init) | AEPE | zero flow | ratio | AEPE covisible | "
             "AEPE all known | px3 | seconds |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]:.3f} | {r[2]:.3f} | {r[3]:.3f} | {r[4]:.3f} | {r[5]:.3f} "
                     f"| {r[6]:.3f} | {r[7]:.0f} |")
    lines += paired({r[0]: r[1] for r in rows})
    (out / "pilot.md").write_text("\n".join(lines) + "\n")
    (out / "curves.json").write_text(json.dumps(curves, indent=1) + "\n")
    picked = args.runs.split(",") if args.runs else None
    if zero is not None:
        shown = {name: points for name, points in curves.items()
                 if picked is None or any(p in name for p in picked)}
        svg_plot(shown, zero, out / "curves.svg")
    print("\n".join(lines))
    failures = over_ratio(rows, *args.max_ratio, args.check_runs) if args.max_ratio else []
    for failure in failures:
        print(failure, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

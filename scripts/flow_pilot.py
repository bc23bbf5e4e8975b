#!/usr/bin/env python3
"""The flow pilot's table and curves (scripts/flow_pilot.sh): for each fine-tune under
OUT/finetune, its held-out flow figures against zero flow, and its held-out AEPE every
--eval-every steps from its log.jsonl. Writes OUT/pilot.md and OUT/curves.json.

    scripts/flow_pilot.py OUT
"""

import json
import sys
from pathlib import Path


def curve(run):
    """[(steps done, held-out AEPE)] from a fine-tune's log.jsonl."""
    points = []
    for line in (run / "log.jsonl").read_text().splitlines():
        entry = json.loads(line)
        if "heldout" in entry:
            points.append((entry["step"] + 1, entry["heldout"]["aepe"]))
    return points


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    rows, curves = [], {}
    for run in sorted((out / "finetune").iterdir()):
        heldout = run / "heldout.json"
        if not heldout.exists():
            continue
        report = json.loads(heldout.read_text())
        model, zero = report["model"], report["baseline"]
        summary = json.loads((run / "summary.json").read_text())
        rows.append((run.name, model["aepe"], zero["aepe"], model["aepe"] / zero["aepe"],
                     model["aepe_covisible"], model["aepe_all_known"], model["px3"],
                     summary.get("seconds", float("nan"))))
        curves[run.name] = curve(run)
    lines = ["| run (patch, flow scale, init) | AEPE | zero flow | ratio | AEPE covisible | "
             "AEPE all known | px3 | seconds |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]:.3f} | {r[2]:.3f} | {r[3]:.3f} | {r[4]:.3f} | {r[5]:.3f} "
                     f"| {r[6]:.3f} | {r[7]:.0f} |")
    (out / "pilot.md").write_text("\n".join(lines) + "\n")
    (out / "curves.json").write_text(json.dumps(curves, indent=1) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())

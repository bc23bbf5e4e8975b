"""scripts/finetune_table.py's flow targets on made-up fine-tunes (cross-view at most half of zero
flow's; cross-view ahead of random weights and mae by intervals below zero, each half-width within
a quarter of the random-to-cross-view gap), and scripts/finetune_table.sh: its refusals, and
BUDGET=flow, which runs flow_pilot.sh's run D seed by seed as the table's runs, and STUDY, which
measures a co-visibility study's flow fine-tunes instead (here with tools that only write what
the real ones would, and log how they were called)."""

import json
import os
import stat
import subprocess
import sys

import pytest

from conftest import SOURCE_DIR

TABLE = SOURCE_DIR / "scripts" / "finetune_table.py"
SCRIPT = SOURCE_DIR / "scripts" / "finetune_table.sh"
ZERO_FLOW = 5.0


def fake_finetune(out, init, seed, aepe):
    run = out / "finetune" / f"flow-{init}-{seed}"
    run.mkdir(parents=True)
    model = {"aepe": aepe, "aepe_covisible": aepe, "aepe_all_known": aepe + 0.3, "px1": 0.9,
             "px3": aepe / 10, "px5": aepe / 20}
    base = {"aepe": ZERO_FLOW, "aepe_covisible": ZERO_FLOW, "aepe_all_known": 5.3, "px1": 0.97,
            "px3": 0.7, "px5": 0.4, "pairs": 100}
    (run / "heldout.json").write_text(json.dumps({"model": model, "baseline": base}))


def table(out, by_init):
    """finetune_table.py on runs whose AEPE is by_init[init][seed]: (table.md, flow's targets)."""
    seeds = len(by_init["croco"])
    for init, values in by_init.items():
        for seed, aepe in enumerate(values):
            fake_finetune(out, init, seed, aepe)
    done = subprocess.run([sys.executable, str(TABLE), str(out), str(seeds), "flow"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return (out / "table.md").read_text(), json.loads((out / "table.json").read_text())["flow"]


def test_targets_met_when_cross_view_is_under_half_and_its_intervals_are_tight(tmp_path):
    text, flow = table(tmp_path, {"random": [4.5, 4.6, 4.4], "mae": [4.4, 4.5, 4.3],
                                  "croco": [2.4, 2.5, 2.3]})
    targets = flow["targets"]
    assert targets["croco_over_zero_flow"] == pytest.approx(0.48)
    assert targets["croco_over_zero_flow_by_seed"] == pytest.approx([0.48, 0.50, 0.46])
    assert targets["half_of_zero_flow_met"]
    # croco - random is -2.1 at every seed: a half-width of 0; the gap 2.1, its quarter 0.525.
    assert targets["croco-random"] == {"met": True, "half_width": pytest.approx(0.0),
                                         "quarter_gap": pytest.approx(0.525)}
    assert targets["croco-mae"]["met"]
    assert "- cross-view's AEPE over zero flow's: 0.480 (by seed: 0.480, 0.500, 0.460); " \
        "at most 0.5: met" in text
    assert "- croco - random: -2.100 ± 0.000 px, half-width 0.000 against a quarter of the " \
        "random-to-cross-view gap, 0.525; the interval is below zero: met" in text


def test_a_miss_says_by_how_much_and_a_wide_interval_is_not_met(tmp_path):
    # D's five seeds at 30,000 steps over a zero flow of 5.528 px, scaled to 5 px: 0.516 of it.
    croco = [2.689, 2.794, 3.271, 2.834, 2.661]
    croco = [ZERO_FLOW * a / 5.528 for a in croco]
    random = [c + d for c, d in zip(croco, [2.6, 0.5, 1.9, 0.4, 2.4])]  # a gap of 1.56 px
    mae = [c + 1.0 for c in croco]
    text, flow = table(tmp_path, {"random": random, "mae": mae, "croco": croco})
    targets = flow["targets"]
    assert targets["croco_over_zero_flow"] == pytest.approx(0.516, abs=5e-4)
    assert not targets["half_of_zero_flow_met"]
    assert "at most 0.5: missed by 0.016" in text
    # Differences -2.6, -0.5, -1.9, -0.4, -2.4: sd 1.0455, t(4) 2.776, half-width 1.298 against
    # a quarter of 1.56 = 0.39. The interval is below zero, the criterion is not met.
    r = targets["croco-random"]
    assert r["half_width"] == pytest.approx(1.2979, abs=1e-3)
    assert r["quarter_gap"] == pytest.approx(0.39)
    assert not r["met"]
    assert "0.39" in text and "the interval is below zero: not met" in text
    assert targets["croco-mae"]["met"]  # 1.0 ahead at every seed


def test_cross_view_behind_mae_is_not_met(tmp_path):
    _, flow = table(tmp_path, {"random": [4.5, 4.6, 4.4], "mae": [2.0, 2.1, 1.9],
                               "croco": [2.4, 2.5, 2.3]})
    # croco - mae is +0.4 at every seed: an interval clear of zero, but above it.
    assert flow["targets"]["croco-mae"]["met"] is False
    assert flow["targets"]["croco-random"]["met"] is True


def test_one_seed_decides_nothing_on_intervals(tmp_path):
    text, flow = table(tmp_path, {"random": [4.5], "mae": [4.4], "croco": [2.4]})
    assert flow["targets"]["half_of_zero_flow_met"]
    assert flow["targets"]["croco-random"] == {"met": False, "half_width": None,
                                                 "quarter_gap": pytest.approx(0.525)}
    assert "- croco - mae: one seed, no interval: not decided" in text


# The scripts' settings, which a caller's environment must not bring into the tests.
SETTINGS = ["BUDGET", "TASKS", "HOMES", "PATCH_SIZE", "AMP", "PRETRAIN_EPOCHS", "FINETUNE_EPOCHS",
            "POSE_BLR", "PRETRAIN_ONLY", "FINETUNE_STEPS", "EVAL_EVERY", "INITS", "POS_EMBED",
            "MAX_RATIO", "SEEDS", "PATCHES", "SCALES", "FLOORPLANS", "PRETRAIN_FLOORPLANS",
            "WIDE_PAIRS", "FLOW_PAIRS", "PRETRAIN_STEPS", "BUILD_DIR", "STUDY"]


def run_script(out, *args, **env):
    clean = {k: v for k, v in os.environ.items() if k not in SETTINGS}
    return subprocess.run(["bash", str(SCRIPT), str(out), *args], capture_output=True, text=True,
                          env={**clean, **env}, timeout=120)


@pytest.mark.parametrize("budget", ["Flow", "large", "small flow"])
def test_an_unknown_budget_is_refused_naming_it(tmp_path, budget):
    done = run_script(tmp_path / "out", BUDGET=budget)
    assert done.returncode == 2
    assert done.stderr == f"finetune_table.sh: BUDGET is small or flow, not '{budget}'\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("seeds", ["0", "-1", "three", "100", "07", "2 3"])
def test_seeds_must_be_a_whole_number_from_1_to_99(tmp_path, seeds):
    done = run_script(tmp_path / "out", seeds, BUDGET="flow")
    assert done.returncode == 2
    assert done.stderr == \
        f"finetune_table.sh: SEEDS is a whole number from 1 to 99, not '{seeds}'\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name,value", [("HOMES", "6"), ("PATCH_SIZE", "8"), ("AMP", "none"),
                                        ("PRETRAIN_EPOCHS", "5"), ("FINETUNE_EPOCHS", "2"),
                                        ("POSE_BLR", "1e-3"), ("PRETRAIN_ONLY", "1")])
def test_the_flow_budget_refuses_the_small_budgets_settings(tmp_path, name, value):
    done = run_script(tmp_path / "out", BUDGET="flow", **{name: value})
    assert done.returncode == 2
    assert done.stderr == f"finetune_table.sh: BUDGET=flow has settings of its own; {name} is " \
        "for BUDGET=small\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("steps", ["0", "-5", "2e4", "many"])
def test_the_flow_budget_refuses_bad_finetune_steps(tmp_path, steps):
    done = run_script(tmp_path / "out", BUDGET="flow", FINETUNE_STEPS=steps)
    assert done.returncode == 2
    assert done.stderr == \
        f"finetune_table.sh: FINETUNE_STEPS is a whole number from 1, not '{steps}'\n"


def test_an_out_holds_one_budgets_runs(tmp_path):
    out = tmp_path / "out"
    (out / "finetune" / "flow-croco-0").mkdir(parents=True)  # a small-budget OUT of before
    done = run_script(out, BUDGET="flow")
    assert done.returncode == 2
    assert done.stderr == f"finetune_table.sh: {out} holds BUDGET=small's runs, not flow's: " \
        "give another OUT\n"
    (out / "budget").write_text("flow\n")
    done = run_script(out)
    assert done.returncode == 2
    assert done.stderr == f"finetune_table.sh: {out} holds BUDGET=flow's runs, not small's: " \
        "give another OUT\n"
    assert sorted(p.name for p in out.iterdir()) == ["budget", "finetune"]


def test_the_flow_budget_refuses_other_tasks(tmp_path):
    done = run_script(tmp_path / "out", BUDGET="flow", TASKS="flow depth")
    assert done.returncode == 2
    assert done.stderr == "finetune_table.sh: BUDGET=flow fine-tunes flow alone, not TASKS " \
        "'flow depth'\n"
    assert not (tmp_path / "out").exists()


# Stand-ins for the tools: each logs its arguments and writes what flow_pilot.sh and the tables
# read. A fine-tune's AEPE depends on its initialisation and seed, so the table can be checked.
FAKE_TOOL = r"""#!/usr/bin/env python3
import json, os, pathlib, sys
args = sys.argv[1:]
name = pathlib.Path(sys.argv[0]).name
with open(os.environ["FAKE_LOG"], "a") as log:
    log.write(json.dumps([name] + args) + "\n")
if "--evaluate" in args:  # a study's fine-tune, whose AEPE its folder's fake.json gives
    ckpt = pathlib.Path(args[args.index("--checkpoint") + 1])
    aepe = json.loads((ckpt.parent / "fake.json").read_text())["aepe"]
    base = {"aepe": 5.0, "aepe_covisible": 5.0, "aepe_all_known": 5.3, "px1": 0.97, "px3": 0.7,
            "px5": 0.4, "pairs": 100}
    model = dict(base, aepe=aepe, aepe_covisible=aepe, aepe_all_known=aepe + 0.3)
    print("evaluating", file=sys.stderr)
    print(json.dumps({"baseline": base, "model": model}))
    sys.exit(0)
out = pathlib.Path(args[args.index("--out") + 1])
out.mkdir(parents=True, exist_ok=True)
if name == "generate_pairs":
    scenes = args[args.index("--scenes") + 1:args.index("--out")]
    per = int(args[args.index("--pairs-per-scene") + 1])
    (out / "summary.json").write_text(json.dumps({"pairs": per * len(scenes)}))
elif name == "pretrain":
    (out / "summary.json").write_text("{}")
elif name == "finetune":
    init, seed = args[args.index("--init") + 1], int(args[args.index("--seed") + 1])
    kind = "random" if init == "random" else ("mae" if "pretrain-mae" in init else "croco")
    aepe = {"random": 4.7, "mae": 4.6, "croco": 2.6}[kind] + 0.01 * seed
    model = {"aepe": aepe, "aepe_covisible": aepe, "aepe_all_known": aepe + 0.3, "px1": 0.9,
             "px3": 0.3, "px5": 0.1}
    base = {"aepe": 5.5, "aepe_covisible": 5.5, "aepe_all_known": 5.8, "px1": 0.97, "px3": 0.77,
            "px5": 0.47, "pairs": 100}
    (out / "heldout.json").write_text(json.dumps({"model": model, "baseline": base}))
    (out / "summary.json").write_text(json.dumps({"seconds": 1.0}))
    (out / "log.jsonl").write_text(json.dumps({"step": 1999, "heldout": model}) + "\n")
"""


def fake_tools(tmp_path):
    tools = tmp_path / "build" / "tools"
    tools.mkdir(parents=True)
    for name in ["make_scenes", "generate_pairs", "pretrain", "finetune"]:
        path = tools / name
        path.write_text(FAKE_TOOL)
        path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(tmp_path / "build")


def test_the_flow_budget_runs_the_pilots_run_d_seed_by_seed(tmp_path):
    fake_tools(tmp_path)
    log, out = tmp_path / "calls.jsonl", tmp_path / "out"
    # A caller's flow_pilot.sh settings are overridden: with these, the runs would have other
    # names, mae would be missing and the pilot would fail its ratio check (exit 1).
    done = run_script(out, "2", BUDGET="flow", BUILD_DIR=str(tmp_path / "build"),
                      FAKE_LOG=str(log), INITS="random croco", POS_EMBED="RoPE100",
                      MAX_RATIO="croco=0.1")
    assert done.returncode == 0, done.stderr
    calls = [json.loads(line) for line in log.read_text().splitlines()]

    def opt(call, flag):
        return call[call.index(flag) + 1]

    scenes = [c for c in calls if c[0] == "make_scenes"]
    assert sorted((opt(c, "--random"), opt(c, "--seed")) for c in scenes) == [("40", "5"),
                                                                              ("80", "6")]
    pretrains = [c for c in calls if c[0] == "pretrain"]
    assert sorted(opt(c, "--task") for c in pretrains) == ["croco", "mae"]
    for c in pretrains:
        assert (opt(c, "--max-steps"), opt(c, "--patch-size"), opt(c, "--batch-size")) == \
            ("20000", "16", "16")
        assert len(c[c.index("--data") + 1:c.index("--task")]) == 2  # the 42 scenes and the 80
    finetunes = [c for c in calls if c[0] == "finetune"]
    assert len(finetunes) == 6
    assert sorted((opt(c, "--seed"), opt(c, "--init").split("/")[-2] if "/" in opt(c, "--init")
                   else "random") for c in finetunes) == \
        [(s, i) for s in "01" for i in sorted(["random", "pretrain-mae-p16-s20000-f40+80",
                                               "pretrain-croco-p16-s20000-f40+80"])]
    for c in finetunes:
        assert (opt(c, "--max-steps"), opt(c, "--flow-scale"), opt(c, "--batch-size")) == \
            ("20000", "0", "8")
    for init in ["random", "mae", "croco"]:
        for seed in [0, 1]:
            assert os.readlink(out / "finetune" / f"flow-{init}-{seed}") == \
                f"p16-scale0-{init}-s20000-f40+80-n150-20000" + (f"-seed{seed}" if seed else "")
    assert (out / "budget").read_text() == "flow\n"
    flow = json.loads((out / "table.json").read_text())["flow"]
    assert flow["random"]["aepe"][0] == pytest.approx(4.705)
    assert flow["mae"]["aepe"][0] == pytest.approx(4.605)
    assert flow["croco"]["aepe"][0] == pytest.approx(2.605)
    assert flow["targets"]["croco_over_zero_flow_by_seed"] == pytest.approx([2.6 / 5.5, 2.61 / 5.5])
    assert flow["targets"]["croco-random"]["met"]
    assert "at most 0.5: met" in done.stdout
    # A second call finds every run done and only writes the table again.
    rerun = run_script(out, "2", BUDGET="flow", BUILD_DIR=str(tmp_path / "build"),
                       FAKE_LOG=str(log))
    assert rerun.returncode == 0, rerun.stderr
    assert len(log.read_text().splitlines()) == len(calls)


def fake_study(study, seeds, finished=True):
    """A covis_sweep folder whose flow fine-tunes of random, mae and uniform_0.50 end at AEPE
    4.0, 3.9 and 2.0 px (+ 0.1 a seed); the last seed's uniform_0.50 unfinished unless finished."""
    for seed in range(seeds):
        for set_, aepe in [("random", 4.0), ("mae", 3.9), ("uniform_0.50", 2.0), ("bin_0.95", 1.0)]:
            ft = study / "runs" / set_ / f"seed-{seed}" / "finetune-flow"
            ft.mkdir(parents=True)
            (ft / "checkpoint-last.pth").write_text("")
            (ft / "fake.json").write_text(json.dumps({"aepe": aepe + 0.1 * seed}))
            (ft / "settings.json").write_text(json.dumps(
                {"preset": "tiny", "img_size": 64, "patch_size": 16, "flow_scale": 4.0}))
            if finished or seed < seeds - 1 or set_ != "uniform_0.50":
                (ft / "heldout.json").write_text("{}")


def test_a_study_gives_the_flow_table_seed_by_seed(tmp_path):
    build, log, out, study = fake_tools(tmp_path), tmp_path / "calls.jsonl", tmp_path / "out", \
        tmp_path / "sweep-flow"
    fake_study(study, 3)
    done = run_script(out, "2", BUDGET="flow", STUDY=str(study), BUILD_DIR=build,
                      FAKE_LOG=str(log))
    assert done.returncode == 0, done.stderr
    calls = [json.loads(line) for line in log.read_text().splitlines()]
    assert [c[0] for c in calls] == ["generate_pairs"] + ["finetune"] * 6  # nothing trained
    pairs = calls[0]
    assert pairs[pairs.index("--scenes") + 1:pairs.index("--out")] == ["scenes/studio"]
    for flag, value in [("--pairs-per-scene", "100"), ("--resolution", "64"), ("--seed", "7"),
                        ("--motion", "near"), ("--min-covis", "0.6")]:
        assert pairs[pairs.index(flag) + 1] == value
    checkpoints = sorted(c[c.index("--checkpoint") + 1] for c in calls[1:])
    assert checkpoints == sorted(f"{study}/runs/{s}/seed-{k}/finetune-flow/checkpoint-last.pth"
                                 for s in ["random", "mae", "uniform_0.50"] for k in [0, 1])
    for c in calls[1:]:
        assert [c[c.index(f) + 1] for f in ["--preset", "--img-size", "--patch-size",
                                            "--flow-scale", "--eval-data"]] == \
            ["tiny", "64", "16", "4.0", f"{out}/flow-heldout/pairs-*.tar"]
    flow = json.loads((out / "table.json").read_text())["flow"]
    assert flow["random"]["aepe"][0] == pytest.approx(4.05)
    assert flow["mae"]["aepe"][0] == pytest.approx(3.95)
    assert flow["croco"]["aepe"][0] == pytest.approx(2.05)
    assert flow["targets"]["croco_over_zero_flow_by_seed"] == pytest.approx([0.4, 0.42])
    assert (out / "budget").read_text() == "flow-study\n"
    assert "at most 0.5: met" in done.stdout
    # The next call measures only the seed it adds; an OUT of the pilot's runs is refused.
    more = run_script(out, "3", BUDGET="flow", STUDY=str(study), BUILD_DIR=build,
                      FAKE_LOG=str(log))
    assert more.returncode == 0, more.stderr
    assert len(log.read_text().splitlines()) == len(calls) + 3
    pilot = run_script(out, "3", BUDGET="flow", BUILD_DIR=build, FAKE_LOG=str(log))
    assert pilot.returncode == 2
    assert pilot.stderr == f"finetune_table.sh: {out} holds BUDGET=flow-study's runs, not " \
        "flow's: give another OUT\n"


def test_a_study_seed_not_yet_fine_tuned_is_named_and_nothing_is_measured_twice(tmp_path):
    build, log, out, study = fake_tools(tmp_path), tmp_path / "calls.jsonl", tmp_path / "out", \
        tmp_path / "sweep-flow"
    fake_study(study, 2, finished=False)
    done = run_script(out, "2", BUDGET="flow", STUDY=str(study), BUILD_DIR=build,
                      FAKE_LOG=str(log))
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1] == f"finetune_table.sh: {study}/runs/uniform_0.50/" \
        "seed-1/finetune-flow: no finished flow fine-tune of uniform_0.50, seed 1"
    assert not (out / "table.md").exists()
    measured = len(log.read_text().splitlines())
    assert measured == 1 + 5  # the held-out pairs and every finished fine-tune
    ft = study / "runs" / "uniform_0.50" / "seed-1" / "finetune-flow"
    (ft / "heldout.json").write_text("{}")
    again = run_script(out, "2", BUDGET="flow", STUDY=str(study), BUILD_DIR=build,
                       FAKE_LOG=str(log))
    assert again.returncode == 0, again.stderr
    assert len(log.read_text().splitlines()) == measured + 1


@pytest.mark.parametrize("env", [{"BUDGET": "small"},
                                 {"BUDGET": "flow", "FINETUNE_STEPS": "30000"}])
def test_a_study_is_taken_as_it_is(tmp_path, env):
    done = run_script(tmp_path / "out", "2", STUDY=str(tmp_path), **env)
    assert done.returncode == 2
    assert done.stderr == "finetune_table.sh: STUDY takes the study's flow fine-tunes as they " \
        "are: BUDGET=flow, without FINETUNE_STEPS\n"
    assert not (tmp_path / "out").exists()

"""scripts/flow_pilot.py on made-up fine-tunes: the table, and the seed-by-seed pairing of
initialisations that decides whether pre-training pays (docs/finetune.md, the pilot)."""

import json
import subprocess
import sys

from conftest import SOURCE_DIR

SCRIPT = SOURCE_DIR / "scripts" / "flow_pilot.py"
CONFIG = "s20000-f40+80-n150-20000"


def fake_run(out, name, aepe, zero=5.5):
    """A fine-tune's folder as finetune writes it: held-out figures, summary and two evaluations."""
    run = out / "finetune" / name
    run.mkdir(parents=True)
    figures = {"aepe": aepe, "aepe_covisible": aepe - 0.01, "aepe_all_known": aepe + 0.3,
               "px3": aepe / 10}
    (run / "heldout.json").write_text(json.dumps(
        {"model": figures, "baseline": {"aepe": zero}}))
    (run / "summary.json").write_text(json.dumps({"seconds": 12.0}))
    log = [{"step": 999, "heldout": {"aepe": zero - 0.1}}, {"step": 1999, "heldout": figures}]
    (run / "log.jsonl").write_text("".join(json.dumps(e) + "\n" for e in log))


def name(init, seed, config=CONFIG):
    return f"p16-scale0-{init}-{config}" + (f"-seed{seed}" if seed else "")


def pilot(out):
    done = subprocess.run([sys.executable, str(SCRIPT), str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return (out / "pilot.md").read_text()


def paired_rows(text):
    """{(configuration, pair): [seeds, difference, half-width / difference]} from pilot.md."""
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 5 and " - " in cells[1]:
            rows[(cells[0], cells[1])] = [cells[2], cells[3], cells[4]]
    return rows


def test_initialisations_are_paired_seed_by_seed(tmp_path):
    for seed, (random, croco) in enumerate([(5.0, 3.0), (5.2, 3.5), (5.1, 3.3)]):
        fake_run(tmp_path, name("random", seed), random)
        fake_run(tmp_path, name("croco", seed), croco)
    fake_run(tmp_path, name("mae", 0), 4.0)  # one seed: nothing to pair it with
    rows = paired_rows(pilot(tmp_path))
    # Differences 2.0, 1.7, 1.8: mean 1.833, sd 0.1528, t(2) 4.303, so 0.379 either side.
    assert rows == {(f"p16-scale0-{CONFIG}", "random - croco"): ["3", "1.833 ± 0.379", "0.21"]}


def test_only_the_seeds_both_have_are_paired(tmp_path):
    for seed, aepe in enumerate([5.0, 5.2, 5.1]):
        fake_run(tmp_path, name("random", seed), aepe)
    fake_run(tmp_path, name("croco", 0), 4.0)
    fake_run(tmp_path, name("croco", 2), 4.5)
    rows = paired_rows(pilot(tmp_path))
    # Seeds 0 and 2: differences 1.0 and 0.6, mean 0.8, sd 0.2828, t(1) 12.706: 2.541.
    assert rows == {(f"p16-scale0-{CONFIG}", "random - croco"): ["2", "0.800 ± 2.541", "3.18"]}


def test_other_budgets_and_unfinished_runs_are_not_paired(tmp_path):
    for seed in (0, 1):
        fake_run(tmp_path, name("random", seed), 5.0 + seed / 10)
        fake_run(tmp_path, name("croco", seed, "s20000-f40+80-n150-30000"), 2.7 + seed / 10)
    (tmp_path / "finetune" / name("croco", 1)).mkdir()  # killed before its held-out figures
    text = pilot(tmp_path)
    assert paired_rows(text) == {}
    assert "Paired over seeds" not in text
    table = [line for line in text.splitlines() if line.startswith("| p16")]
    assert len(table) == 4
    assert f"| {name('croco', 0, 's20000-f40+80-n150-30000')} | 2.700 | 5.500 | 0.491 |" in text


def max_ratio(out, *args):
    return subprocess.run([sys.executable, str(SCRIPT), str(out), *args], capture_output=True,
                          text=True)


def test_max_ratio_fails_naming_each_run_above_it(tmp_path):
    fake_run(tmp_path, name("croco", 0), 3.80)  # 0.691 of zero flow's 5.5
    fake_run(tmp_path, name("croco", 1), 3.90)  # 0.709
    fake_run(tmp_path, name("random", 0), 5.00)  # 0.909: another initialisation, not checked
    done = max_ratio(tmp_path, "--max-ratio", "croco=0.7")
    assert done.returncode == 1
    failures = done.stderr.strip().splitlines()
    assert failures == [f"flow_pilot: {name('croco', 1)}: held-out AEPE 3.900 px is 0.709 of "
                        "zero flow's 5.500, above 0.7"]
    assert (tmp_path / "pilot.md").exists()  # the table is written either way
    assert max_ratio(tmp_path, "--max-ratio", "croco=0.71").returncode == 0
    assert max_ratio(tmp_path, "--max-ratio", "random=0.91").returncode == 0
    assert max_ratio(tmp_path, "--max-ratio", "random=0.91").stderr == ""


def test_max_ratio_fails_when_no_run_of_the_init_finished(tmp_path):
    fake_run(tmp_path, name("random", 0), 5.0)
    (tmp_path / "finetune" / name("croco", 0)).mkdir()  # killed before its held-out figures
    done = max_ratio(tmp_path, "--max-ratio", "croco=0.7")
    assert done.returncode == 1
    assert done.stderr.strip() == "flow_pilot: no finished fine-tune from croco"


def test_max_ratio_refuses_bad_values(tmp_path):
    fake_run(tmp_path, name("croco", 0), 3.0)
    for bad in ("croco", "croco=", "croco=small", "dino=0.7", "croco=nan", "croco=inf",
                "croco=0", "croco=-1"):
        done = max_ratio(tmp_path, "--max-ratio", bad)
        assert done.returncode == 2, bad
        assert "--max-ratio" in done.stderr.splitlines()[-1]
    done = max_ratio(tmp_path / "absent", "--max-ratio", "croco=0.7")
    assert done.returncode == 1
    assert done.stderr.strip() == f"flow_pilot: {tmp_path / 'absent' / 'finetune'}: no such folder"
    done = max_ratio(tmp_path, "--check-runs", name("croco", 0))
    assert done.returncode == 2
    assert "--check-runs needs --max-ratio" in done.stderr


def test_check_runs_checks_the_runs_named_alone(tmp_path):
    fake_run(tmp_path, name("croco", 0), 3.0)  # 0.545: this call's run
    fake_run(tmp_path, name("croco", 0, "s20000-f40+80-n150-800"), 5.0)  # another budget's, 0.909
    this = name("croco", 0)
    assert max_ratio(tmp_path, "--max-ratio", "croco=0.7").returncode == 1
    assert max_ratio(tmp_path, "--max-ratio", "croco=0.7", "--check-runs", this).returncode == 0
    # A named run of the init that has not finished fails, even when another one passes.
    unfinished = name("croco", 1)
    (tmp_path / "finetune" / unfinished).mkdir()
    done = max_ratio(tmp_path, "--max-ratio", "croco=0.7", "--check-runs", f"{this},{unfinished}")
    assert done.returncode == 1
    assert done.stderr.strip() == f"flow_pilot: {unfinished}: not finished (no heldout.json)"
    # Runs of other initialisations in the list are not checked.
    done = max_ratio(tmp_path, "--max-ratio", "croco=0.7", "--check-runs",
                     f"{this},{name('random', 1)}")
    assert done.returncode == 0, done.stderr

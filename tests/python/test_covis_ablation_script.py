"""scripts/covis_ablation.sh refuses, in one line that names the culprit and before it builds or
renders anything: a BUDGET, NSEEDS, FIRST_SEED or PROCESSES it does not know (an empty one means
the default), and an OUT whose scenes were made with other options (FURNISH)."""

import os
import signal
import subprocess

import pytest

from conftest import SOURCE_DIR

SCRIPT = SOURCE_DIR / "scripts" / "covis_ablation.sh"


def run(out, **env):
    """The script on OUT; if it got past its checks it is stopped, with whatever it started."""
    proc = subprocess.Popen(["bash", str(SCRIPT), str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, **env},
                            start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the script went past its checks")
    return proc.returncode, stderr


@pytest.mark.parametrize("budget", ["Flow", "fast", "study flow"])
def test_an_unknown_budget_is_refused_naming_it(tmp_path, budget):
    code, stderr = run(tmp_path / "out", BUDGET=budget)
    assert code == 2
    assert stderr == f"covis_ablation.sh: BUDGET is study or flow, not '{budget}'\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("seeds", ["0", "-1", "two", "1.5", "3 4", "07", "1000"])
def test_nseeds_must_be_a_whole_number_from_1_to_999(tmp_path, seeds):
    code, stderr = run(tmp_path / "out", BUDGET="flow", NSEEDS=seeds)
    assert code == 2
    assert stderr == f"covis_ablation.sh: NSEEDS is a whole number from 1 to 999, not '{seeds}'\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("first,seeds", [("-1", "3"), ("one", "3"), ("01", "3"), ("1 2", "3"),
                                         ("998", "3"), ("1000", "1")])
def test_first_seed_must_leave_every_seed_index_below_1000(tmp_path, first, seeds):
    code, stderr = run(tmp_path / "out", BUDGET="flow", NSEEDS=seeds, FIRST_SEED=first)
    assert code == 2
    assert stderr == ("covis_ablation.sh: FIRST_SEED is a whole number from 0 and FIRST_SEED + "
                      f"NSEEDS at most 1000, not '{first}'\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("processes", ["0", "65", "two", "2 2", "02"])
def test_processes_must_be_a_whole_number_from_1_to_64(tmp_path, processes):
    code, stderr = run(tmp_path / "out", PROCESSES=processes)
    assert code == 2
    assert stderr == ("covis_ablation.sh: PROCESSES is a whole number from 1 to 64, "
                      f"not '{processes}'\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("budget,folder", [("study", "heldout"), ("flow", "heldout"),
                                           ("study", ""), ("flow", "plans40"), ("flow", "plans80")])
def test_scenes_made_with_other_options_are_refused(tmp_path, budget, folder):
    # Furnished scenes (FURNISH=1) in an OUT now run without FURNISH: nothing is reused or remade.
    scenes = tmp_path / "out" / "scenes"
    made = scenes / folder
    made.mkdir(parents=True)
    furnished = {"heldout": "make_scenes --random 1 --seed 99 --furnish --models heldout",
                 "": "study --furnish --models train",
                 "plans40": "make_scenes --random 40 --seed 5 --furnish --models train",
                 "plans80": "make_scenes --random 80 --seed 6 --furnish --models train"}[folder]
    (made / ".done").write_text(furnished + "\n")
    code, stderr = run(tmp_path / "out", BUDGET=budget)
    assert code == 2
    plain = furnished.replace(" --furnish --models heldout", "").replace(
        " --furnish --models train", "")
    assert stderr == (f"covis_ablation.sh: {made} was made with '{furnished}', "
                      f"not '{plain}': give another OUT\n")
    assert sorted(p.name for p in scenes.rglob("*")) == sorted(filter(None, [folder, ".done"]))

"""scripts/covis_ablation.sh refuses a BUDGET or SEEDS it does not know, in one line that names
them, before it builds or renders anything (an empty one means the default)."""

import os
import subprocess

import pytest

from conftest import SOURCE_DIR

SCRIPT = SOURCE_DIR / "scripts" / "covis_ablation.sh"


def run(tmp_path, **env):
    out = tmp_path / "out"
    done = subprocess.run(["bash", str(SCRIPT), str(out)], capture_output=True, text=True,
                          env={**os.environ, **env}, timeout=60)
    return done, out


@pytest.mark.parametrize("budget", ["Flow", "fast", "study flow"])
def test_an_unknown_budget_is_refused_naming_it(tmp_path, budget):
    done, out = run(tmp_path, BUDGET=budget)
    assert done.returncode == 2
    assert done.stderr == f"covis_ablation.sh: BUDGET is study or flow, not '{budget}'\n"
    assert not out.exists()


@pytest.mark.parametrize("seeds", ["0", "-1", "two", "1.5", "3 4", "07"])
def test_seeds_must_be_a_positive_whole_number(tmp_path, seeds):
    done, out = run(tmp_path, BUDGET="flow", SEEDS=seeds)
    assert done.returncode == 2
    assert done.stderr == f"covis_ablation.sh: SEEDS is a positive whole number, not '{seeds}'\n"
    assert not out.exists()

#!/usr/bin/env python3
"""Which of the skipped tests of a run CI allows (scripts/test.sh runs this after ctest).

usage: scripts/skip_policy.py [--require-all] CTEST_JUNIT [PYTEST_JUNIT]

CTEST_JUNIT is ctest's --output-junit file; each skipped test's reason is the message of its
GTEST_SKIP() (the lines between gtest's "Skipped" and "[  SKIPPED ]" in its output). PYTEST_JUNIT
is the Python tests' --junitxml file (tests/CMakeLists.txt), read when the ctest test "python" ran.
Only the tests of this run count, so the policy follows CTEST_ARGS.

A skip is allowed when its test and its reason both match an entry of ALLOWED (and the entry's
release, when it names one, is this machine's; a CUDA skip only where the machine has no NVIDIA
GPU, neither /dev/nvidia0 nor one that `nvidia-smi -L` lists); every other skip is a failure. --require-all makes
every skip a failure, the allowed ones included. Exit status: 0, or 1 on a failure.
"""

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Allowed:
    what: str  # the kind of skip, as docs/releases.md lists it
    tests: str  # full match of the test's name
    reason: str  # full match of its GTEST_SKIP() message
    why: str
    debian: str = ""  # VERSION_ID of the only Debian release where it is allowed ("" any)
    without_gpu: bool = False  # allowed only on a machine with no NVIDIA GPU


# The skips allowed on CI's machines (Debian 12, and Debian 13 in a chroot). docs/releases.md,
# "Skips", lists them; keep the two the same.
ALLOWED = (
    Allowed("CUDA without a GPU",
            tests=r"Cuda\.\w+|Pretrain\.CudaStep",
            reason=r"no CUDA device",
            why="Debian's LibTorch is built without CUDA and CI's machines have no GPU; these run "
                "on a GPU machine",
            without_gpu=True),
    Allowed("torchrun on Debian 13's torch",
            tests=r"Torchrun\.\w+",
            reason=r"this torchrun cannot start its rendezvous store \(python3-torch built without "
                   r"libuv; .*",
            why="Debian 13's python3-torch 2.6 has no libuv, which torchrun's rendezvous asks "
                "for (docs/scale.md, \"torchrun\")",
            debian="13"),
    Allowed("the pthread-OpenBLAS warning where the OpenMP OpenBLAS is installed",
            tests=r"Pretrain\.WarnsOnThePthreadOpenBlas",
            reason=r"libopenblas0-pthread is not installed: the OpenMP OpenBLAS is the only one",
            why="scripts/setup.sh installs only the OpenMP OpenBLAS, and the test needs both "
                "builds"),
)

GTEST_REASON = re.compile(r"^[^\n]*: Skipped\n(.*?)\n?\[  SKIPPED \]", re.S | re.M)


def debian_release():
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("VERSION_ID="):
                return line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    return ""


def ctest_skips(path):
    """(test, reason) of each test ctest did not pass or fail, and whether "python" ran."""
    skips, python_ran = [], False
    for case in ET.parse(path).getroot().iter("testcase"):
        name = case.get("name", "")
        skipped = case.find("skipped")
        if skipped is None:
            python_ran |= name == "python"
            continue
        output = case.findtext("system-out") or ""
        found = GTEST_REASON.search(output)
        if found:
            reason = found.group(1).strip()
        else:  # not run, disabled, or a skip that printed no gtest message
            reason = f"({skipped.get('message', 'skipped')}) {output.strip()}".strip()
        skips.append((name, reason or "(no reason given)"))
    return skips, python_ran


def pytest_skips(path):
    skips = []
    for case in ET.parse(path).getroot().iter("testcase"):
        skipped = case.find("skipped")
        if skipped is not None:
            module = case.get("classname", "")
            name = f"python: {module + '::' if module else ''}{case.get('name', '')}"
            reason = skipped.get("message", "")
            if reason in ("", "collection skipped"):  # a whole module: its reason is in the text
                reason = (skipped.text or "").strip() or reason
            skips.append((name, reason or "(no reason given)"))
    return skips


def gpu_present():
    """Whether this machine has an NVIDIA GPU: a device node, or one that nvidia-smi lists."""
    if Path("/dev/nvidia0").exists():
        return True
    try:
        listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return False
    return listed.returncode == 0 and "GPU" in listed.stdout


def allowed_by(test, reason, release, has_gpu):
    for rule in ALLOWED:
        if (re.fullmatch(rule.tests, test) and re.fullmatch(rule.reason, reason, re.S)
                and rule.debian in ("", release) and not (rule.without_gpu and has_gpu)):
            return rule
    return None


def main(argv):
    require_all = "--require-all" in argv
    files = [a for a in argv if a != "--require-all"]
    if not 1 <= len(files) <= 2 or any(f.startswith("-") for f in files):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    if not Path(files[0]).is_file():
        print(f"skip policy: ctest wrote no {files[0]}: which tests skipped is unknown")
        return 1
    skips, python_ran = ctest_skips(files[0])
    if python_ran and len(files) == 2:
        if Path(files[1]).is_file():
            skips += pytest_skips(files[1])
        else:
            skips.append(("python", f"its skips are unknown: pytest wrote no {files[1]}"))

    release = debian_release()
    has_gpu = gpu_present() if skips else False
    if has_gpu:
        print("skip policy: this machine has an NVIDIA GPU: no CUDA test may skip")
    allowed, refused = {}, []
    for test, reason in skips:
        rule = allowed_by(test, reason, release, has_gpu)
        if rule:
            allowed.setdefault(rule, []).append((test, reason))
        else:
            refused.append((test, reason))

    def show(test, reason):
        lines = reason.splitlines() or [""]
        print(f"    {test}: {lines[0]}")
        for line in lines[1:]:
            print(f"      {line}")

    if allowed:
        print("skip policy: skips allowed on CI's machines (scripts/skip_policy.py, docs/releases.md):")
        for rule, tests in allowed.items():
            print(f"  {rule.what}: {rule.why}")
            for test, reason in tests:
                show(test, reason)
    if refused:
        print("skip policy: skips NOT allowed (each counts as a failure):")
        for test, reason in refused:
            show(test, reason)
    n_allowed = sum(len(t) for t in allowed.values())
    if refused:
        print(f"skip policy: FAILED: {len(refused)} skip(s) not allowed, {n_allowed} allowed")
        return 1
    if require_all and n_allowed:
        names = ", ".join(test for tests in allowed.values() for test, _ in tests)
        print(f"skip policy: FAILED (--require-all): {n_allowed} test(s) skipped: {names}")
        return 1
    print(f"skip policy: {n_allowed} skip(s), all allowed" if n_allowed else "skip policy: no skips")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

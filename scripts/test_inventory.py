#!/usr/bin/env python3
"""Whether a build registered every test it should have (scripts/test.sh runs this after ctest).

usage: scripts/test_inventory.py check BUILD_DIR [CTEST_JUNIT]
       scripts/test_inventory.py write BUILD_DIR

A dependency that is missing leaves tests out without a failure: no pybind11 or numpy and the
Python test is never added, no GoogleTest and tests/ adds nothing, no Draco and the Draco glTF
tests are compiled out. So tests/registered_tests.txt lists every test a full build registers,
each with its module (the test executable, or "python"), and `check` compares it with what
`ctest --show-only=json-v1` lists in BUILD_DIR. Modules that the build's own options leave out on
purpose (PAIRCAST_WITH_TORCH=OFF and PAIRCAST_SANITIZE, as `scripts/test.sh --sanitize` builds;
PAIRCAST_WITH_RENDER=OFF; PAIRCAST_BUILD_PYTHON=OFF), read from BUILD_DIR/CMakeCache.txt, are not expected. Every other
listed test that is not registered fails the run, named with its module; a registered test that
the list lacks fails it too, so that the list stays whole.

With CTEST_JUNIT (ctest's --output-junit file of the run), `check` also fails when the run ran no
test at all: a CTEST_ARGS filter that matched nothing.

`write` rewrites the list from BUILD_DIR, which must be a full build (every option on).
Exit status: 0; 1 when a check fails; 2 on a usage error.
"""

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

LIST = Path(__file__).resolve().parent.parent / "tests" / "registered_tests.txt"
HEADER = """\
# Every test a full build registers (every PAIRCAST_* option on, every package of
# scripts/setup.sh installed): MODULE TEST, one a line. scripts/test.sh fails when a build
# registers fewer or more (scripts/test_inventory.py). After adding or removing a test, rewrite it
# from a full build: scripts/test_inventory.py write build
"""
# The modules each option builds; a module not named here is built whatever the options.
TORCH_MODULES = {"model", "trainer", "gpu", "sweep", "reliability", "finetune", "launch"}
RENDER_MODULES = {"util", "render", "furnish", "covis", "dataset", "trainer", "reliability", "finetune",
                  "launch", "python"}


def plain(name):
    """A test's name without the parameter gtest prints after it ("  # GetParam() = ..."), whose
    form differs between GoogleTest and CMake versions."""
    return re.split(r"\s+#\s", name, maxsplit=1)[0].strip()


def registered(build_dir):
    """{test: module} of the tests ctest lists in build_dir."""
    out = subprocess.run(["ctest", "--show-only=json-v1"], cwd=build_dir, check=True,
                         capture_output=True, text=True).stdout
    tests = {}
    for test in json.loads(out).get("tests", []):
        command = test.get("command") or [""]
        executable = Path(command[0]).name
        module = re.sub(r"_tests$", "", executable) if executable.endswith("_tests") else test["name"]
        tests[plain(test["name"])] = module
    return tests


def read_list():
    tests = {}
    for number, line in enumerate(LIST.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split(None, 1)
        if len(parts) != 2:
            raise SystemExit(f"{LIST}:{number}: expected 'MODULE TEST', got '{line}'")
        tests[plain(parts[1])] = parts[0]
    return tests


def left_out_on_purpose(build_dir):
    """The modules the build's options leave out, from its CMakeCache.txt."""
    cache = (Path(build_dir) / "CMakeCache.txt").read_text()

    def off(option):
        found = re.search(rf"^{option}:BOOL=(\S+)", cache, re.M)
        return bool(found) and found.group(1).upper() in ("OFF", "0", "FALSE", "NO")

    modules = set()
    if off("PAIRCAST_WITH_TORCH"):
        modules |= TORCH_MODULES
    if off("PAIRCAST_WITH_RENDER"):
        modules |= RENDER_MODULES
    sanitized = re.search(r"^PAIRCAST_SANITIZE:\w+=(\S+)", cache, re.M)
    if off("PAIRCAST_BUILD_PYTHON") or sanitized:  # sanitized builds leave Python out
        modules.add("python")
    return modules


def junit_ran_tests(path):
    root = ET.parse(path).getroot()
    return sum(1 for _ in root.iter("testcase"))


def check(build_dir, junit):
    expected, found = read_list(), registered(build_dir)
    skipped_modules = left_out_on_purpose(build_dir)
    missing = {t: m for t, m in expected.items() if m not in skipped_modules and t not in found}
    extra = {t: m for t, m in found.items() if t not in expected}
    failed = False
    if missing:
        failed = True
        by_module = {}
        for test, module in sorted(missing.items()):
            by_module.setdefault(module, []).append(test)
        print(f"test inventory: FAILED: {len(missing)} listed test(s) not registered by this build "
              "(a package missing? see scripts/setup.sh):")
        for module, tests in sorted(by_module.items()):
            listed = sum(1 for m in expected.values() if m == module)
            whole = " (the whole module)" if len(tests) == listed else ""
            print(f"  {module}: {len(tests)} of {listed}{whole}: {', '.join(tests[:8])}"
                  + (f", ... {len(tests) - 8} more" if len(tests) > 8 else ""))
    if extra:
        failed = True
        print(f"test inventory: FAILED: {len(extra)} registered test(s) not in {LIST.name}: "
              f"{', '.join(sorted(extra)[:8])}" + (" ..." if len(extra) > 8 else ""))
        print(f"  add them: scripts/test_inventory.py write {build_dir}")
    if junit is not None:
        ran = junit_ran_tests(junit) if Path(junit).is_file() else 0
        if ran == 0:
            failed = True
            print("test inventory: FAILED: ctest ran no test (a CTEST_ARGS filter that matches "
                  "nothing?)")
    if not failed:
        left = f", modules left out by the build's options: {' '.join(sorted(skipped_modules))}" \
            if skipped_modules else ""
        print(f"test inventory: all {len(found)} expected tests registered{left}")
    return 1 if failed else 0


def write(build_dir):
    if left_out_on_purpose(build_dir):
        print(f"test inventory: {build_dir} is not a full build (an option leaves modules out)")
        return 1
    found = registered(build_dir)
    lines = sorted(f"{module} {test}" for test, module in found.items())
    LIST.write_text(HEADER + "\n".join(lines) + "\n")
    print(f"test inventory: wrote {len(lines)} tests to {LIST}")
    return 0


def main(argv):
    if len(argv) >= 2 and argv[0] == "check" and len(argv) <= 3:
        return check(argv[1], argv[2] if len(argv) == 3 else None)
    if len(argv) == 2 and argv[0] == "write":
        return write(argv[1])
    print(__doc__.split("\n\n")[1], file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

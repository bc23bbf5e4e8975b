"""scripts/test_inventory.py and scripts/skip_policy.py, on made-up builds and JUnit files: what
CI's test command fails on when a dependency left tests out, a filter matched nothing, or a CUDA
test skipped on a machine that has a GPU."""

import importlib.util
import subprocess
import sys
import textwrap

import pytest

from conftest import SOURCE_DIR

SCRIPTS = SOURCE_DIR / "scripts"


def load(name):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fake_build(path, tests, cache="PAIRCAST_WITH_TORCH:BOOL=ON\nPAIRCAST_SANITIZE:STRING=\n"):
    """A folder ctest reads as a build that registered `tests` ({name: module})."""
    path.mkdir(parents=True, exist_ok=True)
    lines = []
    for name, module in tests.items():
        command = "/usr/bin/python3" if module == "python" else f"{path}/tests/{module}_tests"
        lines.append(f'add_test([=[{name}]=] "{command}" "--gtest_filter={name}")')
    (path / "CTestTestfile.cmake").write_text("\n".join(lines) + "\n")
    (path / "CMakeCache.txt").write_text(cache)
    return path


def junit(path, cases):
    """ctest's JUnit file: cases is [(name, skip output or None)]."""
    body = []
    for name, skip in cases:
        if skip is None:
            body.append(f'<testcase name="{name}" status="run"/>')
        else:
            body.append(f'<testcase name="{name}" status="notrun"><skipped message="skipped"/>'
                        f"<system-out>{skip}</system-out></testcase>")
    path.write_text(f'<testsuite tests="{len(cases)}">{"".join(body)}</testsuite>')
    return path


@pytest.fixture
def inventory(tmp_path, monkeypatch):
    module = load("test_inventory")
    listed = tmp_path / "registered_tests.txt"
    listed.write_text(textwrap.dedent("""\
        # a comment
        render RayCaster.Hits
        render Gltf.DracoMesh
        model CrocoNet.Forward
        python python
        """))
    monkeypatch.setattr(module, "LIST", listed)
    return module


FULL = {"RayCaster.Hits": "render", "Gltf.DracoMesh": "render", "CrocoNet.Forward": "model",
        "python": "python"}


def test_a_full_build_passes(inventory, tmp_path, capsys):
    build = fake_build(tmp_path / "build", FULL)
    assert inventory.check(str(build), str(junit(tmp_path / "j.xml", [("python", None)]))) == 0
    assert "all 4 expected tests registered" in capsys.readouterr().out


def test_a_module_left_out_fails_naming_it(inventory, tmp_path, capsys):
    build = fake_build(tmp_path / "build", {k: v for k, v in FULL.items() if v != "python"})
    assert inventory.check(str(build), None) == 1
    out = capsys.readouterr().out
    assert "python: 1 of 1 (the whole module): python" in out


def test_a_single_test_left_out_fails_naming_it(inventory, tmp_path, capsys):
    build = fake_build(tmp_path / "build", {k: v for k, v in FULL.items() if k != "Gltf.DracoMesh"})
    assert inventory.check(str(build), None) == 1
    assert "render: 1 of 2: Gltf.DracoMesh" in capsys.readouterr().out


def test_a_test_the_list_lacks_fails(inventory, tmp_path, capsys):
    build = fake_build(tmp_path / "build", {**FULL, "RayCaster.New": "render"})
    assert inventory.check(str(build), None) == 1
    assert "not in registered_tests.txt: RayCaster.New" in capsys.readouterr().out


def test_modules_the_options_leave_out_are_not_expected(inventory, tmp_path, capsys):
    sanitized = "PAIRCAST_WITH_TORCH:BOOL=OFF\nPAIRCAST_SANITIZE:STRING=address,undefined\n"
    build = fake_build(tmp_path / "build", {"RayCaster.Hits": "render", "Gltf.DracoMesh": "render"},
                       cache=sanitized)
    assert inventory.check(str(build), None) == 0
    assert "modules left out by the build's options: finetune gpu launch model python" in \
        capsys.readouterr().out


def test_a_run_that_ran_no_test_fails(inventory, tmp_path, capsys):
    build = fake_build(tmp_path / "build", FULL)
    assert inventory.check(str(build), str(junit(tmp_path / "j.xml", []))) == 1
    assert "ctest ran no test" in capsys.readouterr().out
    assert inventory.check(str(build), str(tmp_path / "absent.xml")) == 1


def test_write_refuses_a_partial_build(inventory, tmp_path):
    build = fake_build(tmp_path / "build", FULL, cache="PAIRCAST_WITH_TORCH:BOOL=OFF\n")
    assert inventory.write(str(build)) == 1


def test_the_shipped_list_matches_this_build():
    """The real list against the build these tests run from: the check CI makes."""
    from conftest import BINARY_DIR
    result = subprocess.run([sys.executable, str(SCRIPTS / "test_inventory.py"), "check",
                             str(BINARY_DIR)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


CUDA_SKIP = "gpu_test.cpp:141: Skipped\nno CUDA device\n[  SKIPPED ] Cuda.SdpaForward"


@pytest.mark.parametrize("has_gpu, expected", [(False, 0), (True, 1)])
def test_a_cuda_skip_is_allowed_only_without_a_gpu(tmp_path, monkeypatch, capsys, has_gpu,
                                                   expected):
    policy = load("skip_policy")
    monkeypatch.setattr(policy, "gpu_present", lambda: has_gpu)
    report = junit(tmp_path / "j.xml", [("Cuda.SdpaForward", CUDA_SKIP), ("Shard.Ok", None)])
    assert policy.main([str(report)]) == expected
    out = capsys.readouterr().out
    if has_gpu:
        assert "skips NOT allowed" in out and "Cuda.SdpaForward: no CUDA device" in out
    else:
        assert "1 skip(s), all allowed" in out

"""Checkpoints written by `pretrain` load in the installed torch with torch.load's own defaults
(weights_only=True since PyTorch 2.6), as a naver/croco user would load them."""

import inspect
import pickle
import subprocess

import pytest

from conftest import tool

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def checkpoint(croco_pairs, tmp_path_factory):
    out = tmp_path_factory.mktemp("train")
    result = subprocess.run(
        [tool("pretrain"), "--data", str(croco_pairs / "pairs-*.tar"), "--preset", "tiny",
         "--img-size", "64", "--batch-size", "2", "--max-steps", "2", "--out", str(out)],
        capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return out / "checkpoint-last.pth"


def test_the_default_torch_load_reads_a_pretrain_checkpoint(checkpoint):
    ck = torch.load(checkpoint, map_location="cpu")
    assert "mask_token" in ck["model"]
    assert ck["args"]["enc_embed_dim"] > 0
    assert len(ck["optimizer"]["state"]) > 0


def test_weights_only_reads_it_from_torch_2(checkpoint):
    if "weights_only" not in inspect.signature(torch.load).parameters:
        pytest.skip(f"torch {torch.__version__} has no weights_only")
    if int(torch.__version__.split(".")[0]) < 2:
        # 1.13's (Debian 12's) early weights_only unpickler has no BINFLOAT (opcode 71), which
        # any float needs: it refuses every checkpoint with a float, ours included.
        with pytest.raises(pickle.UnpicklingError, match="Unsupported operand 71"):
            torch.load(checkpoint, map_location="cpu", weights_only=True)
        return
    ck = torch.load(checkpoint, map_location="cpu", weights_only=True)
    assert set(ck["model"]) == set(torch.load(checkpoint, map_location="cpu")["model"])


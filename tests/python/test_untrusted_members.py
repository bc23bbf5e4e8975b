"""Shards whose members lie about their size, given to the real commands (finetune, pretrain) and
to the Python loaders (ShardPairs, ShardLoader with flow=True): a 12-byte .flo member claiming
65,536 x 65,536 (32 GiB of floats), a depth EXR whose data window claims 65,536 x 65,536, a JPEG
whose frame header claims 60,000 x 60,000. Each gives one line naming the shard and the member,
or a skip with a warning that names them, never a crash; the peak memory of each run is measured
(the limit is 1 GiB: without the size checks, the .flo member alone asks for 32 GiB)."""

import io
import json
import struct
import subprocess
import sys
import tarfile
import time

import pytest

from conftest import tool

PEAK_LIMIT_KB = 1 << 20  # 1 GiB
FLO_MAGIC = 202021.25


def lying_flo(data):
    return struct.pack("<fii", FLO_MAGIC, 65536, 65536)  # 12 bytes, no values


def lying_exr(data):
    """The member's own header with its data window widened to 65,536 x 65,536."""
    key = b"dataWindow\0box2i\0" + struct.pack("<i", 16)
    at = data.index(key) + len(key)
    return data[:at] + struct.pack("<iiii", 0, 0, 65535, 65535) + data[at + 16:]


def lying_jpeg(data):
    """The member's own frame header (SOF0) claiming 60,000 x 60,000 pixels."""
    at = data.index(b"\xff\xc0")
    return data[:at + 5] + struct.pack(">HH", 60000, 60000) + data[at + 9:]


def craft(source, out, member_suffix, lie):
    """A copy of shard `source` at `out` whose first member ending with `member_suffix` is
    replaced by lie(its bytes). Returns that member's name."""
    replaced = None
    with tarfile.open(source) as src, tarfile.open(out, "w", format=tarfile.USTAR_FORMAT) as dst:
        for info in src.getmembers():
            data = src.extractfile(info).read()
            if replaced is None and info.name.endswith(member_suffix):
                data, replaced = lie(data), info.name
                info = tarfile.TarInfo(info.name)
                info.mtime = 0
            info.size = len(data)
            dst.addfile(info, io.BytesIO(data))
    assert replaced, f"no member ending with {member_suffix} in {source}"
    return replaced


def peak_rss_of(args):
    """Runs args in a fresh Python that waits for it and reports its peak RSS:
    (returncode, stdout, stderr, peak RSS in KiB)."""
    probe = ("import resource, subprocess, sys\n"
             "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
             "sys.stdout.write(r.stdout)\n"
             "sys.stderr.write(r.stderr)\n"
             "print('peak_rss_kb', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
             "sys.exit(r.returncode)\n")
    result = subprocess.run([sys.executable, "-c", probe, *map(str, args)], capture_output=True,
                            text=True, timeout=300)
    out, _, peak = result.stdout.rpartition("peak_rss_kb ")
    return result.returncode, out, result.stderr, int(peak)


CASES = [(".1.flow.flo", lying_flo), (".1.depth.exr", lying_exr), (".1.jpg", lying_jpeg)]


@pytest.fixture(scope="module", params=CASES, ids=["flo", "exr", "jpeg"])
def crafted(request, flow_shards, tmp_path_factory):
    """(shard path, replaced member) for each kind of lie, from the first flow shard."""
    suffix, lie = request.param
    out = tmp_path_factory.mktemp("crafted") / "pairs-000000.tar"
    source = sorted(flow_shards.glob("pairs-*.tar"))[0]
    member = craft(source, out, suffix, lie)
    return out, member


def test_finetune_names_the_shard_and_the_member_in_one_line(crafted, tmp_path):
    shard, member = crafted
    start = time.monotonic()
    rc, _, err, peak = peak_rss_of([tool("finetune"), "--data", shard, "--out", tmp_path / "run",
                                    "--img-size", "64", "--head", "linear", "--batch-size", "2",
                                    "--max-steps", "2", "--quiet"])
    elapsed = time.monotonic() - start
    lines = err.strip().splitlines()
    assert rc == 1, err
    assert len(lines) == 1, err
    assert str(shard) in lines[0] and member in lines[0], lines[0]
    assert peak < PEAK_LIMIT_KB, f"peak RSS {peak} KiB"
    assert elapsed < 60, f"{elapsed:.1f} s"


def test_pretrain_trains_past_the_member(crafted, tmp_path):
    """pretrain reads the images alone: a lying image is skipped with a warning naming it; a
    lying flow or depth member is never read."""
    shard, member = crafted
    rc, _, err, peak = peak_rss_of([tool("pretrain"), "--data", shard, "--preset", "tiny",
                                    "--img-size", "32", "--batch-size", "1", "--max-steps", "2",
                                    "--workers", "1", "--out", tmp_path / "run", "--quiet"])
    assert rc == 0, err
    assert (member in err) == member.endswith(".jpg"), err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["steps"] == 2
    assert peak < PEAK_LIMIT_KB, f"peak RSS {peak} KiB"


LOADERS = """
import sys, warnings
sys.path.insert(0, sys.argv[1])
from paircast.torch import ShardLoader, ShardPairs
pattern, kind = sys.argv[2], sys.argv[3]
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    if kind == "ShardPairs":
        got = len(list(ShardPairs(pattern, crop=48, flow=True, depth=True)))
    else:
        got = sum(len(b[0]) for b in ShardLoader(pattern, batch_size=2, crop=48, flow=True,
                                                  threads=2))
for w in caught:
    print("warning:", str(w.message).replace("\\n", " "))
print("pairs:", got)
"""


@pytest.mark.parametrize("kind", ["ShardPairs", "ShardLoader"])
def test_python_loaders_skip_the_member_with_a_warning(crafted, kind):
    """Both loaders skip a sample whose member they read and cannot decode, with a warning that
    names the shard and the member, and keep the other two pairs. ShardLoader reads no depth."""
    from conftest import BINARY_DIR
    shard, member = crafted
    rc, out, err, peak = peak_rss_of([sys.executable, "-c", LOADERS, BINARY_DIR / "python",
                                      shard, kind])
    assert rc == 0, err
    read = not (kind == "ShardLoader" and member.endswith(".exr"))
    warnings = [line for line in out.splitlines() if line.startswith("warning:")]
    assert f"pairs: {2 if read else 3}" in out, out
    if read:
        assert any(str(shard) in w and member in w for w in warnings), out
    else:
        assert not warnings, out
    assert peak < PEAK_LIMIT_KB, f"peak RSS {peak} KiB"

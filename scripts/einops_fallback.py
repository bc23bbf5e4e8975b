"""naver/croco's DPT block (models/dpt_block.py) imports einops for one rearrange pattern. Where
einops is not installed (Debian 12 has no package of it, and a GPU machine without network cannot
pip it), install() puts in a module that does that pattern alone and refuses any other, so that
the official classes load unchanged. With einops installed it does nothing.
"""
import sys
import types

PATTERN = "b (nh nw) c -> b c nh nw"


def _rearrange(x, pattern, **sizes):
    if " ".join(pattern.split()) != PATTERN:
        raise NotImplementedError(f"einops is not installed; this stand-in does only '{PATTERN}'")
    b, _, c = x.shape
    return x.reshape(b, sizes["nh"], sizes["nw"], c).permute(0, 3, 1, 2)


def _repeat(*_args, **_kwargs):
    raise NotImplementedError("einops is not installed; this stand-in has no repeat")


def install():
    try:
        import einops  # noqa: F401
    except ImportError:
        module = types.ModuleType("einops")
        module.rearrange, module.repeat = _rearrange, _repeat
        sys.modules["einops"] = module

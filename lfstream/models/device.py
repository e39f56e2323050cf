"""Where the networks run: the one check of a ``device`` argument, and the precision their
inference runs at there."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from lfstream.errors import LFValueError

#: ``precision`` arguments of the networks' inference functions: ``"auto"`` (bfloat16 where
#: :func:`native_bfloat16`, else float32), ``"float32"`` or ``"bfloat16"``.
PRECISIONS = ("auto", "float32", "bfloat16")


def check_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"``/``"cuda:N"`` (when torch sees a GPU); a clear error otherwise."""
    if device not in ("cpu", "cuda") and not str(device).startswith("cuda:"):
        raise LFValueError(f"device: 'cpu' or 'cuda', got {device!r}")
    if str(device).startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise LFValueError(f"device={device!r}: torch sees no CUDA GPU on this machine; use --device cpu")
    return str(device)


def native_bfloat16(device: str) -> bool:
    """Whether ``device`` is a CPU whose instruction set multiplies bfloat16 natively
    (AVX512-BF16 or AMX-BF16), where oneDNN's bfloat16 convolutions beat float32 ones. GPUs
    keep float32 (their timings and outputs were measured so); a CPU without these
    instructions too (it would emulate bfloat16, slower than float32)."""
    if str(device) != "cpu":
        return False
    import torch

    capabilities = getattr(torch.cpu, "get_capabilities", dict)()
    return bool(capabilities.get("avx512_bf16") or capabilities.get("amx_bf16"))


def check_precision(precision: str) -> str:
    """A ``precision`` of :data:`PRECISIONS`, or a clear error (torch is not imported)."""
    if precision not in PRECISIONS:
        raise LFValueError(f"precision: one of {', '.join(PRECISIONS)}, got {precision!r}")
    return precision


def inference_bfloat16(device: str, precision: str = "auto") -> bool:
    """Whether inference on ``device`` runs in bfloat16 for a ``precision`` of
    :data:`PRECISIONS`."""
    check_precision(precision)
    return precision == "bfloat16" or (precision == "auto" and native_bfloat16(device))


@contextmanager
def inference_precision(device: str, precision: str = "auto") -> Iterator[bool]:
    """A block whose network calls on ``device`` run at ``precision``: bfloat16 is torch's
    autocast (this thread only: the convolutions and matrix products in bfloat16, the rest
    as its policy keeps it, so a network's float32 output stays float32); yields whether it
    is on. On a CPU with native bfloat16 (AVX512-BF16, AMX) the networks run markedly faster,
    and the decoded light fields stay within 0.01 dB and 0.00003 MSSIM of float32 on the six
    shared samples."""
    if not inference_bfloat16(device, precision):
        yield False
        return
    import torch

    with torch.autocast(device_type=str(device).split(":")[0], dtype=torch.bfloat16):
        yield True


__all__ = ["PRECISIONS", "check_device", "check_precision", "inference_bfloat16", "inference_precision", "native_bfloat16"]

"""Where the networks run: the one check of a ``device`` argument."""

from __future__ import annotations

from lfstream.errors import LFValueError


def check_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"``/``"cuda:N"`` (when torch sees a GPU); a clear error otherwise."""
    if device not in ("cpu", "cuda") and not str(device).startswith("cuda:"):
        raise LFValueError(f"device: 'cpu' or 'cuda', got {device!r}")
    if str(device).startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise LFValueError(f"device={device!r}: torch sees no CUDA GPU on this machine; use --device cpu")
    return str(device)


__all__ = ["check_device"]

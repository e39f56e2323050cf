"""What travels on the queues between the stages."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfstream.codec.decoder import DecodedFrame


@dataclass
class SourceFrame:
    """Producer -> encoder: one input frame ``(U, V, H, W, 3)``."""

    seq: int
    lf: np.ndarray


@dataclass
class StackFrame:
    """Refocus -> sink -> metrics: a decoded frame and its focal stack."""

    seq: int
    decoded: DecodedFrame
    stack: np.ndarray | None = None  # (K, H, W, 3) uint8
    slopes: np.ndarray | None = None  # (K,) the planes the stack was rendered at


__all__ = ["SourceFrame", "StackFrame"]

"""The refocus stage's renderer: the focal planes (the scene's own range by default), the
focal-stack method, and skip (b)."""

from __future__ import annotations

import json
import time

import numpy as np

from lfstream.codec.decoder import DecodedFrame
from lfstream.errors import LFStreamError, LFValueError
from lfstream.optics import SEED_ALPHAS, slopes_from_alphas
from lfstream.stream.config import StreamConfig

#: Consecutive frames whose disparity range leaves the planes' range before they move.
REFIT_AFTER_FRAMES = 3


class Refocuser:
    """Renders the focal stack of decoded frames with the chosen method and skip (b).

    Focal planes: ``config.alphas == "auto"`` (the default) fits them to the scene on the
    first frame (:func:`lfstream.refocus.scene_slopes`: its robust disparity range, planes
    a depth of field apart) and keeps them while the scene stays in range — stable from
    frame to frame — refitting (same number of planes) after the scene's range has left
    them by more than a plane spacing for :data:`REFIT_AFTER_FRAMES` frames; ``"seed"``
    the seed's sixteen alphas; a tuple, those alphas.
    """

    def __init__(self, config: StreamConfig, views: tuple[int, int]) -> None:
        self.config = config
        self.views = views
        self.auto = config.alphas == "auto"
        alphas = SEED_ALPHAS if config.alphas in ("auto", "seed") else config.alphas
        self.slopes = slopes_from_alphas(alphas)
        self.updates: list[dict] = []  # frame -> slopes, each time the planes were (re)fitted
        self._outside = 0
        self.method = config.refocus
        self.reason = "requested"

    def fit_planes(self, f: DecodedFrame) -> None:
        """Auto focus: fit the planes on the first frame, refit when the scene left them."""
        if not self.auto:
            return
        from lfstream.refocus.planes import plane_spacing, scene_slopes

        if not self.updates:
            self._set_slopes(f.seq, scene_slopes(f.disparity, self.views))
            return
        lo, hi = np.percentile(f.disparity, [2, 98]) if f.disparity.size else (0.0, 0.0)
        step = plane_spacing(self.views)
        left = lo < self.slopes[0] - step or hi > self.slopes[-1] + step or \
            (hi - lo) < 0.5 * (self.slopes[-1] - self.slopes[0]) - step
        self._outside = self._outside + 1 if left else 0
        if self._outside >= REFIT_AFTER_FRAMES:
            k = len(self.slopes)
            self._set_slopes(f.seq, scene_slopes(f.disparity, self.views, max_planes=k, min_planes=k))
            self._outside = 0

    def _set_slopes(self, seq: int, slopes: np.ndarray) -> None:
        self.slopes = np.asarray(slopes, np.float64)
        self.updates.append({"frame": int(seq), "slopes": [round(float(s), 6) for s in self.slopes]})

    def planes(self) -> list[dict]:
        """The current planes: index, slope and alpha (``None`` for slopes >= 1)."""
        from lfstream.refocus.planes import plane_records

        return plane_records(self.slopes, self.config.camera)

    def _refnet_applicable(self) -> bool:
        from lfstream.models.manifest import manifest_entry

        entry = manifest_entry("refnet", "fast")
        seed = slopes_from_alphas(SEED_ALPHAS)
        return (entry is not None and tuple(entry["config"]["views"]) == tuple(self.views)
                and self.slopes.shape == seed.shape and np.allclose(self.slopes, seed))

    def choose(self, lf: np.ndarray) -> None:
        """``auto``: RefNet when it is applicable, faster than SaS on this device and within
        30 dB PSNR of SaS on this frame; otherwise SaS. Measured on the first frame (after a
        warm-up) and remembered in the cache folder, so every later run on this machine
        makes the same choice without measuring again."""
        from lfstream.metrics import psnr
        from lfstream.refocus import focal_stack

        if self.method != "auto":
            if self.method == "refnet" and not self._refnet_applicable():
                raise LFValueError("refocus=refnet: the shipped RefNet takes 7x7 views and the seed's 16 alphas "
                                   "(--alphas seed)")
            return
        if not self._refnet_applicable():
            self.method, self.reason = "sas", ("RefNet not applicable (it renders the seed's 16 alphas of 7x7 views; "
                                               "the planes or the grid differ)")
            return
        key = self._choice_key(lf)
        cached = _read_choices().get(key)
        if cached is not None:
            self.method = cached["method"]
            self.reason = f"{cached['reason']} (measured on an earlier run on this machine, cached)"
            return
        focal_stack(lf, slopes=self.slopes)  # warm-up: the kernels load before anything is timed
        t0 = time.perf_counter()
        ref = focal_stack(lf, slopes=self.slopes)
        t_sas = time.perf_counter() - t0
        focal_stack(lf, method="refnet", device=self.config.device)  # warm-up
        t0 = time.perf_counter()
        net = focal_stack(lf, method="refnet", device=self.config.device)
        t_net = time.perf_counter() - t0
        err = float(np.mean(psnr(ref, net)))
        if t_net < t_sas and err >= 30.0:
            self.method = "refnet"
        else:
            self.method = "sas"
        self.reason = (f"measured on frame 0 ({self.config.device}): SaS {t_sas * 1e3:.0f} ms, RefNet {t_net * 1e3:.0f} ms "
                       f"at {err:.1f} dB vs SaS")
        _write_choice(key, {"method": self.method, "reason": self.reason})

    def _choice_key(self, lf: np.ndarray) -> str:
        """What the measured choice depends on: device, light-field shape, planes, versions."""
        import torch

        from lfstream.models.manifest import manifest_entry
        from lfstream.version import __version__

        entry = manifest_entry("refnet", "fast") or {}
        return "|".join(str(x) for x in (self.config.device, lf.shape, np.round(self.slopes, 6).tolist(), __version__,
                                         torch.__version__, torch.get_num_threads(), entry.get("sha256")))

    def render(self, f: DecodedFrame, lf: np.ndarray | None = None) -> np.ndarray | None:
        """The focal stack ``(K, H, W, 3)`` uint8 of a decoded frame (``None``: no refocusing);
        ``lf``: the frame's views to refocus where not ``f.lf`` (reordered to the convention's
        grid, :func:`lfstream.lightfield.canonical_views`)."""
        from lfstream.refocus import focal_stack

        if self.method == "none":
            return None
        lf = f.lf if lf is None else lf
        extra = {"device": self.config.device} if self.method == "refnet" else {}
        return focal_stack(lf, slopes=self.slopes, method=self.method, **extra)


_CHOICES = "refocus-choices.json"


def _read_choices() -> dict:
    from lfstream.stream.sources import cache_dir

    folder = cache_dir()
    try:
        return json.loads((folder / _CHOICES).read_text()) if folder is not None else {}
    except (OSError, ValueError):
        return {}


def _write_choice(key: str, choice: dict) -> None:
    """Remembers a measured choice so that later runs make the same one without measuring."""
    from lfstream.io._fs import atomic_write_text
    from lfstream.stream.sources import cache_dir

    folder = cache_dir()
    if folder is None:
        return
    choices = _read_choices()
    choices[key] = choice
    try:
        atomic_write_text(folder / _CHOICES, json.dumps(choices, indent=1, sort_keys=True))
    except LFStreamError:
        pass  # a cache that cannot be written only costs the next run a measurement


__all__ = ["Refocuser"]

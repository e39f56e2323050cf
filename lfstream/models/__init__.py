"""The seed's three residual CNNs, their losses, and the registry of shipped weights.

- :mod:`~lfstream.models.jpeg_hance`: JPEG-Hance, restores the decoded centre view.
- :mod:`~lfstream.models.depth_net`: Depth-Net, per-view disparity for the warp.
- :mod:`~lfstream.models.refnet`: RefNet, a light field to a focal stack.
- :mod:`~lfstream.models.layers`: the shared bottleneck block; :mod:`~lfstream.models.losses`
  the seed's losses; :mod:`~lfstream.models.warp` the differentiable warp.
- :mod:`~lfstream.models.registry`: ``(name, preset)`` -> network, shipped weights checked
  by SHA-256 (``manifest.json`` in ``weights/``), one cached loader.

Importing this package imports neither torch nor the networks: each name below loads its
module on first use, so ``lfstream.models.device`` and ``lfstream.models.manifest`` stay
light (the stream checks devices and shipped weights without torch).
"""

from importlib import import_module

_LAZY = {
    "check_device": "lfstream.models.device",
    "manifest_entry": "lfstream.models.manifest",
    **{name: "lfstream.models.registry" for name in ("MODEL_NAMES", "PRESETS", "REGISTRY", "ModelSpec", "list_models",
                                                      "load_model", "shipped_model", "spec")},
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'lfstream.models' has no attribute {name!r}")


__all__ = ["MODEL_NAMES", "PRESETS", "REGISTRY", "ModelSpec", "check_device", "list_models", "load_model",
           "manifest_entry", "shipped_model", "spec"]

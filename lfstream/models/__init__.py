"""The seed's three residual CNNs, their losses, and the registry of shipped weights.

- :mod:`~lfstream.models.jpeg_hance`: JPEG-Hance, restores the decoded centre view.
- :mod:`~lfstream.models.depth_net`: Depth-Net, per-view disparity for the warp.
- :mod:`~lfstream.models.refnet`: RefNet, a light field to a focal stack.
- :mod:`~lfstream.models.layers`: the shared bottleneck block; :mod:`~lfstream.models.losses`
  the seed's losses; :mod:`~lfstream.models.warp` the differentiable warp.
- :mod:`~lfstream.models.registry`: ``(name, preset)`` -> network, shipped weights checked
  by SHA-256 (``manifest.json`` in ``weights/``), one cached loader.

Importing this package imports torch; the codec and CLI import it only when a network runs.
"""

from lfstream.models.device import check_device
from lfstream.models.registry import (
    MODEL_NAMES,
    PRESETS,
    REGISTRY,
    ModelSpec,
    list_models,
    load_model,
    manifest_entry,
    shipped_model,
    spec,
)

__all__ = ["MODEL_NAMES", "PRESETS", "REGISTRY", "ModelSpec", "check_device", "list_models", "load_model",
           "manifest_entry", "shipped_model", "spec"]

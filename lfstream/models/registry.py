"""Model registry and shipped weights.

Every network is registered once under ``(name, preset)``; registering a name twice is an
error (no silent overwrite). Trained weights live in ``lfstream/models/weights/`` as
``NAME-PRESET.pt`` (a ``state_dict`` plus the architecture config) and are described in
``lfstream/models/weights/manifest.json``: file, SHA-256, parameter count, training recipe and
reference metrics. Loading checks the SHA-256 and the parameter count and never touches
the network; a missing or corrupt file raises :class:`lfstream.WeightsError`.
"""

from __future__ import annotations

import functools
import io
import json
import os
from dataclasses import asdict, dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from lfstream.errors import LFValueError, WeightsError
from lfstream.io._fs import atomic_open, atomic_write_text
from lfstream.models.layers import count_params
from lfstream.models.manifest import MANIFEST, WEIGHTS_DIR, manifest_entry, read_manifest, sha256_file  # noqa: F401

PRESETS = ("paper", "fast")


@dataclass(frozen=True)
class ModelSpec:
    """A registered network: how to build it from its config."""

    name: str
    preset: str
    model_cls: type
    config_cls: type
    config: Any

    def build(self, **overrides) -> nn.Module:
        from dataclasses import replace

        return self.model_cls(replace(self.config, **overrides) if overrides else self.config)


REGISTRY: dict[tuple[str, str], ModelSpec] = {}


def register(spec: ModelSpec) -> None:
    key = (spec.name, spec.preset)
    if key in REGISTRY:
        raise LFValueError(f"model {spec.name}/{spec.preset} is already registered")
    REGISTRY[key] = spec


def _register_builtin() -> None:
    from lfstream.models.centre_depth import CentreDepthConfig, CentreDepthNet
    from lfstream.models.depth_net import DEPTH_PRESETS, DepthNet, DepthNetConfig, DepthRefiner, DepthRefinerConfig
    from lfstream.models.jpeg_hance import HANCE_PRESETS, HanceConfig, JPEGHance
    from lfstream.models.refnet import REFNET_PRESETS, RefNet, RefNetConfig

    for preset in PRESETS:
        register(ModelSpec("jpeg_hance", preset, JPEGHance, HanceConfig, HANCE_PRESETS[preset]))
        register(ModelSpec("refnet", preset, RefNet, RefNetConfig, REFNET_PRESETS[preset]))
    # Depth-Net: the seed's monocular network (paper) and the hint refiner (fast)
    register(ModelSpec("depth_net", "paper", DepthNet, DepthNetConfig, DEPTH_PRESETS["paper"]))
    register(ModelSpec("depth_net", "fast", DepthRefiner, DepthRefinerConfig, DepthRefinerConfig()))
    # the seed's path at a CPU decoder's size: the centre view's disparity from the centre alone
    register(ModelSpec("depth_centre", "fast", CentreDepthNet, CentreDepthConfig, CentreDepthConfig()))


_register_builtin()
MODEL_NAMES = ("jpeg_hance", "depth_net", "depth_centre", "refnet")


def spec(name: str, preset: str = "fast") -> ModelSpec:
    try:
        return REGISTRY[(name, preset)]
    except KeyError:
        known = ", ".join(f"{n}/{p}" for n, p in sorted(REGISTRY))
        raise LFValueError(f"unknown model {name!r} preset {preset!r}; known: {known}") from None


def _tuples(value):
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


def config_from_dict(config_cls: type, data: dict) -> Any:
    names = {f.name for f in fields(config_cls)}
    unknown = set(data) - names
    if unknown:
        raise WeightsError(f"weights config has unknown fields {sorted(unknown)} for {config_cls.__name__}")
    return config_cls(**{k: _tuples(v) for k, v in data.items()})


def load_model(name: str, preset: str = "fast", device: str | torch.device = "cpu",
               path: str | os.PathLike | None = None, sha256: str | None = None) -> nn.Module:
    """Builds a registered network and loads its trained weights (eval mode).

    Args:
        name, preset: the registry key.
        device: where the model lives.
        path: a weights file instead of the shipped one (then ``sha256`` is checked if given).

    Raises:
        WeightsError: no weights ship for it, or the file is missing, corrupt or does not match.
    """
    s = spec(name, preset)
    entry = None
    if path is None:
        entry = manifest_entry(name, preset)
        if entry is None:
            raise WeightsError(f"no trained weights ship for {name}/{preset} (train them with tools/train.py)")
        path = WEIGHTS_DIR / entry["file"]
        sha256 = entry["sha256"]
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: weights file for {name}/{preset} is missing")
    if sha256 is not None and sha256_file(path) != sha256:
        raise WeightsError(f"{path}: SHA-256 does not match the manifest (corrupt or replaced file)")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        config = config_from_dict(s.config_cls, ckpt["config"])
        model = s.model_cls(config)
        model.load_state_dict(ckpt["state_dict"], strict=True)
    except WeightsError:
        raise
    except Exception as exc:  # torch raises many types for a bad checkpoint
        raise WeightsError(f"{path}: not a valid {name} checkpoint ({type(exc).__name__}: {exc})") from exc
    if entry is not None and count_params(model) != entry["params"]:
        raise WeightsError(f"{path}: {count_params(model)} parameters, manifest says {entry['params']}")
    return model.to(device).eval()


@functools.lru_cache(maxsize=16)
def shipped_model(name: str, preset: str = "fast", device: str = "cpu") -> nn.Module:
    """The shipped weights of ``name/preset`` on ``device``, loaded and SHA-checked once per
    process (the pipeline decodes and refocuses frame after frame). Inference only: callers
    must not train or modify the returned module."""
    return load_model(name, preset, device)


def save_checkpoint(model: nn.Module, name: str, preset: str, path: str | os.PathLike) -> str:
    """Writes ``{config, state_dict}`` atomically; returns the file's SHA-256."""
    path = Path(path)
    config = model.config
    payload = {"name": name, "preset": preset, "config": asdict(config) if is_dataclass(config) else dict(config),
               "state_dict": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}}
    # serialised in memory: torch names the archive's root folder after the file it writes,
    # so saving to the temporary name put the process id into the bytes and the SHA-256
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with atomic_open(path) as fh:
        fh.write(buffer.getvalue())
    return sha256_file(path)


def ship_weights(model: nn.Module, name: str, preset: str, recipe: dict, metrics: dict) -> dict:
    """Saves ``model`` as the shipped weights of ``name/preset`` and records it in the manifest."""
    WEIGHTS_DIR.mkdir(exist_ok=True)
    file = f"{name}-{preset}.pt"
    digest = save_checkpoint(model, name, preset, WEIGHTS_DIR / file)
    entry = {"name": name, "preset": preset, "file": file, "sha256": digest, "params": count_params(model),
             "config": asdict(model.config), "recipe": recipe, "metrics": metrics}
    manifest = read_manifest()
    manifest["models"] = [e for e in manifest.get("models", []) if (e["name"], e["preset"]) != (name, preset)]
    manifest["models"].append(entry)
    manifest["models"].sort(key=lambda e: (e["name"], e["preset"]))
    atomic_write_text(MANIFEST, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return entry


def list_models() -> list[dict]:
    """Every registered network and preset, with its parameter count and shipped weights."""
    out = []
    for (name, preset), s in sorted(REGISTRY.items()):
        entry = manifest_entry(name, preset)
        out.append({"name": name, "preset": preset, "params": count_params(s.build()),
                    "weights": str(WEIGHTS_DIR / entry["file"]) if entry else None,
                    "sha256": entry["sha256"] if entry else None,
                    "metrics": entry.get("metrics") if entry else None})
    return out


__all__ = ["ModelSpec", "REGISTRY", "register", "spec", "load_model", "ship_weights", "save_checkpoint",
           "list_models", "shipped_model", "sha256_file", "MODEL_NAMES", "PRESETS", "WEIGHTS_DIR"]

"""Model registry and checkpoints that know their model, features and rig.

A checkpoint is a ``torch.save`` dict (read back with ``weights_only=True``)::

    format, format_version, model_name, model_config (dict), feature_config (dict),
    feature_fingerprint, rig {"bones": [...], "pose_dim": int}, extra (JSON-able dict),
    weights_sha256, state_dict

Loading refuses, with a :class:`~models.errors.CheckpointError` naming the file and
what differs: an unreadable/truncated file, another format version, weights whose
hash does not match (corruption), non-finite weights, a rig other than the expected
bone list, or a feature fingerprint other than the expected one.

The feature fingerprint is ``feature_config["fingerprint"]`` when present (pass
``{**cfg.to_dict(), "fingerprint": cfg.fingerprint()}`` from models.features), else a
SHA-1 of the config's canonical JSON.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import torch
from torch import nn

from models.errors import CheckpointError, ConfigError
from models.networks.baselines import LSTMConfig, LSTMRegressor, make_unet
from models.networks.generator import GeneratorConfig
from models.networks.violin import ViolinConfig, ViolinNet
from models.networks.gcn import GCNConfig, GCNDancer
from models.networks.dtm import DanceToMusic, DTMConfig
from models.networks.dance_vq import DanceVQ, DanceVQConfig

FORMAT = "live-performer-checkpoint"
FORMAT_VERSION = 1

# name -> (config class, fields the name fixes)
MODELS: dict[str, tuple[type, dict[str, Any]]] = {
    "causal": (GeneratorConfig, {"causal": True, "residual": True, "attention": True}),
    "unet_gan": (GeneratorConfig, {"causal": False, "residual": True, "attention": True}),
    "unet_plain": (GeneratorConfig, {"causal": False, "residual": False, "attention": False}),
    "lstm": (LSTMConfig, {}),
    "violin": (ViolinConfig, {}),  # Kao & Su 2020, offline only (models/networks/violin.py)
    "gcn": (GCNConfig, {}),
    "dtm": (DTMConfig, {}),
    "dance_vq": (DanceVQConfig, {}),  # the dancing performer: motion codebook + causal code predictor
}


def build_model(name: str = "causal", config: Any = None) -> nn.Module:
    """Model by registry name: "causal" (default), "unet_gan", "unet_plain" or "lstm".

    ``config``: the name's config dataclass, a dict of its fields, or None (defaults).
    For the U-Nets the name decides ``causal``, ``residual`` and ``attention``.
    """
    if name not in MODELS:
        raise ConfigError(f"unknown model {name!r}; choose one of {sorted(MODELS)}")
    cls, fixed = MODELS[name]
    if config is None:
        config = cls()
    elif isinstance(config, dict):
        config = cls.from_dict(config)
    elif not isinstance(config, cls):
        raise ConfigError(f"model {name!r} takes a {cls.__name__}, got {type(config).__name__}")
    if fixed:
        config = dataclasses.replace(config, **fixed)
    if name == "violin":
        return ViolinNet(config)
    if name == "dtm":
        return DanceToMusic(config)
    if name == "gcn":
        return GCNDancer(config)
    if name == "dance_vq":
        return DanceVQ(config)
    return LSTMRegressor(config) if name == "lstm" else make_unet(config)


def feature_fingerprint(feature_config: dict) -> str:
    """The config's own "fingerprint" entry, else SHA-1 (12 hex) of its canonical JSON."""
    if "fingerprint" in feature_config:
        return str(feature_config["fingerprint"])
    blob = json.dumps(feature_config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _weights_hash(state: dict[str, torch.Tensor]) -> str:
    h = hashlib.sha256()
    for key in sorted(state):
        h.update(key.encode())
        h.update(state[key].detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _check_finite(path: Path, state: dict[str, torch.Tensor]) -> None:
    bad = [k for k, v in state.items() if v.is_floating_point() and not torch.isfinite(v).all()]
    if bad:
        raise CheckpointError(f"non-finite weights in {bad[:3]}", source=path)


def _config_dict(config: Any) -> dict[str, Any]:
    return config.to_dict() if hasattr(config, "to_dict") else dict(config)


def save_checkpoint(
    path: str | os.PathLike,
    model: nn.Module,
    *,
    model_name: str,
    generator_config: Any,
    feature_config: dict,
    rig: dict,
    extra: dict | None = None,
) -> Path:
    """Atomically write ``model`` and its metadata to ``path`` (temp file + rename).

    rig: {"bones": [bone names], "pose_dim": 3 + 4 * len(bones)}, matching the model.
    extra: JSON-serialisable notes (training step, losses, data ...).
    """
    path = Path(path)
    cfg = _config_dict(generator_config)
    bones = [str(b) for b in rig.get("bones", [])]
    pose_dim = int(rig.get("pose_dim", -1))
    if pose_dim != 3 + 4 * len(bones) or pose_dim != cfg.get("pose_dim"):
        raise CheckpointError(
            f"rig has {len(bones)} bones and pose_dim {pose_dim}, model pose_dim {cfg.get('pose_dim')}; "
            "need pose_dim = 3 + 4 * bones on both",
            source=path,
        )
    try:
        json.dumps([cfg, feature_config, extra or {}])
    except TypeError as e:
        raise CheckpointError(f"config, feature_config and extra must be JSON-serialisable: {e}", source=path) from e
    state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
    _check_finite(path, state)  # a diverged model must not replace a good checkpoint
    try:  # fail now, not at load time, if the name/config cannot rebuild this model
        build_model(model_name, cfg).load_state_dict(state, strict=True)
    except (ConfigError, RuntimeError) as e:
        raise CheckpointError(f"model_name {model_name!r} with this config does not fit the model: {e}", source=path) from e
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "model_name": model_name,
        "model_config": cfg,
        "feature_config": dict(feature_config),
        "feature_fingerprint": feature_fingerprint(feature_config),
        "rig": {"bones": bones, "pose_dim": pose_dim},
        "extra": dict(extra or {}),
        "weights_sha256": _weights_hash(state),
        "state_dict": state,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(payload, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _read(path: Path) -> dict:
    if not path.is_file():
        raise CheckpointError("checkpoint file not found", source=path)
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises RuntimeError, EOFError, UnpicklingError, ... on damage
        raise CheckpointError(f"unreadable checkpoint (truncated or corrupt?): {type(e).__name__}: {e}", source=path) from e
    if not isinstance(ck, dict) or ck.get("format") != FORMAT:
        raise CheckpointError(f"not a {FORMAT} file", source=path)
    if ck.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint format version {ck.get('format_version')} != supported {FORMAT_VERSION}", source=path
        )
    return ck


def _check_rig(path: Path, rig: dict, expect_bones: list[str] | tuple[str, ...] | None) -> None:
    if expect_bones is None:
        return
    have, want = list(rig["bones"]), list(expect_bones)
    if have != want:
        diff = [f"#{i}: {a!r} vs {b!r}" for i, (a, b) in enumerate(zip(have, want)) if a != b][:3]
        raise CheckpointError(
            f"checkpoint is for another rig: {len(have)} bones (pose_dim {rig['pose_dim']}) vs expected "
            f"{len(want)} (pose_dim {3 + 4 * len(want)}); first differences (checkpoint vs expected): "
            f"{diff or 'bone count'}",
            source=path,
        )


def load_checkpoint(
    path: str | os.PathLike,
    *,
    expect_feature_fingerprint: str | None = None,
    expect_bones: list[str] | tuple[str, ...] | None = None,
) -> tuple[nn.Module, dict]:
    """Read a checkpoint: returns (model in eval mode, metadata dict without the weights).

    A file torch can read but whose fields are missing or of the wrong type (damaged or
    crafted) is a :class:`CheckpointError` too, never a KeyError or TypeError.
    """
    path = Path(path)
    ck = _read(path)
    try:
        return _load_fields(path, ck, expect_feature_fingerprint, expect_bones)
    except (KeyError, TypeError, AttributeError, ValueError, IndexError, OverflowError) as e:
        raise CheckpointError(f"malformed checkpoint: {type(e).__name__}: {e}", source=path) from None


def _load_fields(
    path: Path, ck: dict, expect_feature_fingerprint: str | None, expect_bones: list[str] | tuple[str, ...] | None
) -> tuple[nn.Module, dict]:
    meta = {k: v for k, v in ck.items() if k != "state_dict"}
    state = ck["state_dict"]
    if _weights_hash(state) != ck.get("weights_sha256"):
        raise CheckpointError("weights do not match their stored SHA-256 (corrupt file)", source=path)
    _check_finite(path, state)
    _check_rig(path, ck["rig"], expect_bones)
    if ck["rig"]["pose_dim"] != ck["model_config"].get("pose_dim"):
        raise CheckpointError(
            f"rig pose_dim {ck['rig']['pose_dim']} != model pose_dim {ck['model_config'].get('pose_dim')}", source=path
        )
    if expect_feature_fingerprint is not None and ck["feature_fingerprint"] != expect_feature_fingerprint:
        raise CheckpointError(
            f"checkpoint was trained on features {ck['feature_fingerprint']!r}, "
            f"expected {expect_feature_fingerprint!r} (feature config {ck['feature_config']})",
            source=path,
        )
    try:
        model = build_model(ck["model_name"], ck["model_config"])
        model.load_state_dict(state, strict=True)
    except (ConfigError, RuntimeError) as e:
        raise CheckpointError(f"weights do not fit model {ck['model_name']!r}: {e}", source=path) from e
    return model.eval(), meta

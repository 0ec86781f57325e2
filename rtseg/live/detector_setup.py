"""The live session's detectors from its configuration (``rtseg.live.pipeline``): each
configured method's validated parameters and the online detectors made with them, and the
BLAS thread limit the live loop and replays run under."""

from __future__ import annotations

from typing import Any

from rtseg.config import ConfigError
from rtseg.detectors.base import OnlineDetector
from rtseg.live.config import SessionConfig


def detector_params(config: SessionConfig) -> dict[str, dict[str, Any]]:
    """Validated parameters of each configured method: ``detectors.params`` (default
    ``config/detectors.toml``) overridden by ``[detectors.<method>]``.  ConfigError names
    the key."""
    from rtseg import detectors as det_mod
    params_file = config["detectors.params"] or None
    try:
        all_params = det_mod.load_params(params_file)
    except (ValueError, OSError) as exc:
        raise ConfigError(f"detectors.params: {exc}") from None
    out = {}
    for m in det_mod.ONLINE_METHODS:     # every override is checked, run or not
        p = dict(all_params.get(m, {}))
        try:
            p.update(det_mod.validate(m, config[f"detectors.{m}"]))
        except ValueError as exc:
            raise ConfigError(f"detectors.{m}: {exc}") from None
        out[m] = p
    return {m: out[m] for m in config["detectors.methods"]}


def make_detectors(config: SessionConfig, frame_rate: float) -> dict[str, OnlineDetector]:
    """The configured online detectors (``detectors.methods``) with ``detector_params``."""
    from rtseg import detectors as det_mod
    out: dict[str, OnlineDetector] = {}
    for m, p in detector_params(config).items():
        try:
            out[m] = det_mod.make_online(m, frame_rate, p)
        except (TypeError, ValueError, KeyError) as exc:
            raise ConfigError(f"detectors.{m}: {exc}") from None
    return out


def _blas_limit(n: int) -> Any:
    """Limit BLAS threads to ``n`` (0: no change); the limiter, or None."""
    if n <= 0:
        return None
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return None
    return threadpool_limits(n, user_api="blas")

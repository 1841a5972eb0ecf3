"""What estimation, reconstruction, identification and diagnosis share: the one noise-level
estimator (:mod:`~dualprobe.models.noise`) and the one exact inverse of a sampled sensor
(:mod:`~dualprobe.models.inverse`)."""

from __future__ import annotations

"""What estimation, reconstruction, identification and diagnosis share: the one noise-level
estimator (:mod:`~dualprobe.models.noise`), the one exact inverse of a sampled sensor
(:mod:`~dualprobe.models.inverse`) and the one treatment of a logger's held readings
(:mod:`~dualprobe.models.held`)."""

from __future__ import annotations

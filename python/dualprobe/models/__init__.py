"""What estimation, reconstruction, identification and diagnosis share: the one noise-level
estimator (:mod:`~dualprobe.models.noise`), the one exact inverse of a sampled sensor
(:mod:`~dualprobe.models.inverse`), the one treatment of a logger's held readings
(:mod:`~dualprobe.models.held`) and the one finite-difference Jacobian
(:mod:`~dualprobe.models.jacobian`)."""

from __future__ import annotations

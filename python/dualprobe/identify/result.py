"""What a transfer-function fit returns (:class:`TfFit`) and the choices it is made with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from dualprobe.io import EstimationError
from dualprobe.models.gain import GAIN_RANGE

__all__ = [
    "GAIN_RANGE",
    "HOLDS",
    "INITIAL_CONDITIONS",
    "Hold",
    "IdentificationError",
    "Initial",
    "TfFit",
    "check_gain",
]


HOLDS = ("foh", "zoh")
INITIAL_CONDITIONS = ("estimate", "steady")
Hold = Literal["foh", "zoh"]
Initial = Literal["estimate", "steady"]


class IdentificationError(EstimationError):
    """The data are valid but no model can be fitted (e.g. a constant input)."""


@dataclass(frozen=True)
class TfFit:
    """Result of :func:`fit_transfer_function`.

    ``taus`` are ordered largest first; ``*_std`` are 1-sigma uncertainties (white-residual
    assumption, see the module docstring). ``initial_state`` is the model state at the first
    sample in output units (first entry = the model output at the first sample).
    """

    order: int
    gain: float
    gain_std: float
    taus: tuple[float, ...]
    taus_std: tuple[float, ...]
    delay: float
    delay_std: float
    delay_estimated: bool
    initial_state: tuple[float, ...]
    initial_state_std: tuple[float, ...]
    sample_interval: float
    n_samples: int
    n_parameters: int
    rmse: float
    fit_percent: float
    aic: float
    aicc: float
    bic: float
    residual_autocorrelation: float
    input_noise_std: float
    hold: str
    initial: str
    parameter_names: tuple[str, ...]
    covariance: tuple[tuple[float, ...], ...]
    n_function_evaluations: int
    offset: float = 0.0
    offset_std: float = 0.0
    offset_estimated: bool = False

    @property
    def model(self) -> str:
        """The fitted transfer function as text, e.g. ``0.99/((1+0.17s)(1+12.3s))``."""
        poles = "".join(f"(1+{tau:.4g}s)" for tau in sorted(self.taus))
        text = f"{self.gain:.4g}/{poles}" if len(self.taus) == 1 else f"{self.gain:.4g}/({poles})"
        if self.delay_estimated:
            text += f"*exp(-{self.delay:.4g}s)"
        if self.offset_estimated:
            text += f" {self.offset:+.4g}"
        return text

    def summary(self) -> str:
        """A short human-readable report."""
        lines = [f"model  {self.model}"]
        lines.append(f"  gain K      = {self.gain:.6g} +/- {self.gain_std:.2g}")
        names = ["tau"] if self.order == 1 else ["tau_a", "tau_b"]
        for name, value, std in zip(names, self.taus, self.taus_std, strict=True):
            lines.append(f"  {name:<11} = {value:.6g} +/- {std:.2g} s")
        if self.delay_estimated:
            lines.append(f"  delay       = {self.delay:.6g} +/- {self.delay_std:.2g} s")
        if self.offset_estimated:
            lines.append(f"  offset      = {self.offset:.6g} +/- {self.offset_std:.2g}")
        lines.append(
            f"fit {self.fit_percent:.2f} % (NRMSE)   RMSE {self.rmse:.4g}   "
            f"AICc {self.aicc:.6g}   BIC {self.bic:.6g}"
        )
        lines.append(
            f"{self.n_samples} samples, Ts = {self.sample_interval:.6g} s, "
            f"{self.n_parameters} parameters, residual lag-1 autocorrelation "
            f"{self.residual_autocorrelation:.2f}"
            + (" (uncertainties optimistic)" if abs(self.residual_autocorrelation) > 0.3 else "")
        )
        if self.input_noise_std > 0:
            lines.append(f"input noise {self.input_noise_std:.3g} included in the uncertainties")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (plain floats, lists)."""
        return {
            "model": self.model,
            "order": self.order,
            "gain": self.gain,
            "gain_std": self.gain_std,
            "taus": list(self.taus),
            "taus_std": list(self.taus_std),
            "delay": self.delay,
            "delay_std": self.delay_std,
            "delay_estimated": self.delay_estimated,
            "initial_state": list(self.initial_state),
            "initial_state_std": list(self.initial_state_std),
            "sample_interval": self.sample_interval,
            "n_samples": self.n_samples,
            "n_parameters": self.n_parameters,
            "rmse": self.rmse,
            "fit_percent": self.fit_percent,
            "aic": self.aic,
            "aicc": self.aicc,
            "bic": self.bic,
            "residual_autocorrelation": self.residual_autocorrelation,
            "input_noise_std": self.input_noise_std,
            "hold": self.hold,
            "initial": self.initial,
            "parameter_names": list(self.parameter_names),
            "covariance": [list(row) for row in self.covariance],
            "offset": self.offset,
            "offset_std": self.offset_std,
            "offset_estimated": self.offset_estimated,
        }




def check_gain(fit: TfFit, bounds: tuple[float, float] = GAIN_RANGE) -> None:
    """Refuse (IdentificationError, exit 3) a static gain outside ``bounds``.

    A gain far from 1 between two temperatures means the columns are in different units or
    scales. The time constants of such a fit are not trustworthy either: an offset between the
    columns that the model cannot take (without ``offset``) is absorbed into them.
    """
    low, high = bounds
    if not low <= fit.gain <= high:
        raise IdentificationError(
            f"identified static gain K = {fit.gain:.4g} is implausible for a temperature sensor "
            f"(expected {low:g}-{high:g}): input and output in different units (e.g. degC "
            "against V)? Convert them, add --offset for a constant difference, or pass "
            "--any-gain to accept it"
        )

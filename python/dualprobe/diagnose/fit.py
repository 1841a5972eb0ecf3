"""Fitting a member of the model family: :class:`ModelFit`, the problem (data, residual,
variable projection of the static map) and the Levenberg-Marquardt fit from several starts."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from dualprobe.diagnose.catalogue import static
from dualprobe.diagnose.catalogue.conditions import EXPONENT_LIMIT
from dualprobe.diagnose.model import Context, held, sensor_state

__all__ = [
    "ModelFit",
    "Problem",
    "best_of",
    "dot",
    "fit_model",
]


@dataclass(frozen=True)
class ModelFit:
    """A fitted member of the model family."""

    effects: tuple[str, ...]  # in the order they were added
    params: dict[str, float]
    prediction: np.ndarray
    residual: np.ndarray
    rmse: float
    fit_percent: float  # 100 (1 - |y - y_hat| / |y - mean y|), as MATLAB compare

    @property
    def n_params(self) -> int:
        return 2 + len(self.effects)  # tau + initial state, one more per effect

    @property
    def mse(self) -> float:
        return self.rmse**2

    @property
    def tau(self) -> float:
        """Main time constant (mean of heating and cooling with hysteresis)."""
        if "tau_heat" in self.params:
            return 0.5 * (self.params["tau_heat"] + self.params["tau_cool"])
        return self.params["tau"]


class _Layout:
    """Vector of the nonlinear parameters of a model with given effects (log time constants)."""

    def __init__(self, effects: Sequence[str], ts: float, duration: float) -> None:
        self.effects = tuple(effects)
        names = ["log_tau_heat", "log_tau_cool"] if "hysteresis" in effects else ["log_tau"]
        names.append("initial")
        if "extra_pole" in effects:
            names.append("log_ratio2")  # tau2 / (smaller main tau) <= 1
        if "dead_time" in effects:
            names.append("delay")
        if "flow_dependence" in effects:
            names.append("flow_exponent")
        if "level_dependence" in effects:
            names.append("level_exponent")
        self.names = names
        self.tau_bounds = (math.log(0.02 * ts), math.log(10.0 * duration))
        self.max_delay = 0.25 * duration
        scale = {"initial": 1.0, "delay": ts}
        self.scale = np.array([scale.get(n, 0.1) for n in names])

    def to_params(self, vector: np.ndarray) -> dict[str, float]:
        """Parameters from an unconstrained vector (Levenberg-Marquardt has no bounds): log time
        constants clipped to a sane range, tau2 / tau = exp(-|v|) <= 1, delay = |v|."""
        v = dict(zip(self.names, (float(x) for x in vector), strict=True))
        lo, hi = self.tau_bounds

        def tau(name: str) -> float:
            return math.exp(min(max(v[name], lo), hi))

        p: dict[str, float] = {"initial": v["initial"]}
        if "log_tau" in v:
            p["tau"] = tau("log_tau")
            main = p["tau"]
        else:
            p["tau_heat"] = tau("log_tau_heat")
            p["tau_cool"] = tau("log_tau_cool")
            main = min(p["tau_heat"], p["tau_cool"])
        if "log_ratio2" in v:
            p["tau2"] = main * math.exp(-min(abs(v["log_ratio2"]), 30.0))
        if "delay" in v:
            p["delay"] = min(abs(v["delay"]), self.max_delay)
        for name in ("flow_exponent", "level_exponent"):
            if name in v:
                p[name] = min(max(v[name], -EXPONENT_LIMIT), EXPONENT_LIMIT)
        return p

    def to_vector(self, p: Mapping[str, float]) -> np.ndarray:
        """Vector for these effects from any parameter set (missing entries get defaults)."""
        tau = p.get("tau", math.sqrt(p.get("tau_heat", 1.0) * p.get("tau_cool", 1.0)))
        values = {
            "log_tau": math.log(tau),
            "log_tau_heat": math.log(p.get("tau_heat", tau)),
            "log_tau_cool": math.log(p.get("tau_cool", tau)),
            "initial": p["initial"],
            "delay": p.get("delay", 0.0),
            "flow_exponent": p.get("flow_exponent", 0.0),
            "level_exponent": p.get("level_exponent", 0.0),
        }
        if "extra_pole" in self.effects:
            main = (
                tau
                if "hysteresis" not in self.effects
                else min(p.get("tau_heat", tau), p.get("tau_cool", tau))
            )
            values["log_ratio2"] = math.log(min(p.get("tau2", 0.1 * main) / main, 1.0))
        return np.array([values[n] for n in self.names])


def dot(a: np.ndarray, b: np.ndarray) -> float:
    # einsum's own loop, not BLAS: OpenBLAS threads waking for every vector product cost
    # milliseconds each on a loaded machine.
    return float(np.einsum("i,i->", a, b))


class Problem:
    """Data of one diagnosis and the residual of any member of the model family."""

    def __init__(
        self,
        u: np.ndarray,
        y: np.ndarray,
        ts: float,
        context: Context,
        constants: Mapping[str, Mapping[str, float]] | None = None,
    ) -> None:
        self.u = u
        self.y = y
        self.ts = ts
        self.context = context
        self.duration = ts * (u.size - 1)
        # parameters not fitted but chosen once for the data (the input sampling convention)
        self.fixed: dict[str, float] = {}
        # parameters an effect brings that are detected or chosen, not fitted (the flow and
        # level references, the logger's refresh period and phase)
        self.constants = {k: dict(v) for k, v in (constants or {}).items()}
        self.y_spread = math.sqrt(dot(y - y.mean(), y - y.mean()))

    def static_solve(
        self, x: np.ndarray, hours: np.ndarray, effects: Sequence[str]
    ) -> tuple[np.ndarray, dict[str, float]]:
        """Residual and static parameters (variable projection: linear least squares)."""
        base = self.y - x
        columns = static.columns(x, hours, effects)
        if not columns:
            return base, {}
        # Normal equations of at most 3 columns, scaled to unit norm (condition <~ 1e6 for
        # levels within 0-1000 degC: far inside double precision), without BLAS.
        cols = [c for _, c in columns]
        norms = np.array([math.sqrt(dot(c, c)) or 1.0 for c in cols])
        gram = np.array([[dot(a, b) for b in cols] for a in cols]) / np.outer(norms, norms)
        rhs = np.array([dot(c, base) for c in cols]) / norms
        try:
            coef = np.linalg.solve(gram, rhs) / norms
        except np.linalg.LinAlgError:
            coef = np.linalg.lstsq(gram, rhs, rcond=None)[0] / norms
        residual = base.copy()
        for c, value in zip(cols, coef, strict=True):
            residual -= value * c
        solved = {}
        for (name, _), value in zip(columns, coef, strict=True):
            solved[name] = float(value) + (1.0 if name == "gain" else 0.0)
        return residual, solved

    def with_fixed(self, p: Mapping[str, float], effects: Sequence[str]) -> dict[str, float]:
        """`p` under this problem's sampling convention (whatever `p` was fitted under), with
        the constants of `effects`."""
        out = {k: v for k, v in p.items() if k != "input_hold"}
        out.update(self.fixed)
        for effect in effects:
            out.update(self.constants.get(effect, {}))
        return out

    def simulate(
        self, effects: Sequence[str], p: Mapping[str, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Sensor state and time (h) as the logger reads them."""
        x = sensor_state(self.u, self.ts, p, self.context)
        return held(x, self.context.hours, p)

    def residual(self, effects: Sequence[str], p: Mapping[str, float]) -> np.ndarray:
        return self.static_solve(*self.simulate(effects, self.with_fixed(p, effects)), effects)[0]

    def sse(self, effects: Sequence[str], p: Mapping[str, float]) -> float:
        r = self.residual(effects, p)
        return dot(r, r)

    def make_fit(self, effects: Sequence[str], p: Mapping[str, float]) -> ModelFit:
        p = self.with_fixed(p, effects)
        residual, linear = self.static_solve(*self.simulate(effects, p), effects)
        params = dict(p)
        params.update(linear)
        prediction = self.y - residual
        sse = dot(residual, residual)
        rmse = math.sqrt(sse / residual.size)
        fit = 100.0 * (1.0 - math.sqrt(sse) / max(self.y_spread, 1e-300))
        return ModelFit(tuple(effects), _ordered(params), prediction, residual, rmse, fit)


_PARAM_ORDER = (
    "tau",
    "tau_heat",
    "tau_cool",
    "tau2",
    "delay",
    "flow_exponent",
    "flow_reference",
    "flow_delay",
    "level_exponent",
    "level_reference",
    "gain",
    "offset",
    "curvature",
    "drift_rate",
    "hold_samples",
    "hold_phase",
    "initial",
    "input_hold",
)


def _ordered(params: Mapping[str, float]) -> dict[str, float]:
    return {k: float(params[k]) for k in _PARAM_ORDER if k in params}


def fit_model(
    problem: Problem, effects: Sequence[str], starts: Sequence[Mapping[str, float]]
) -> ModelFit:
    """Least-squares fit of the model with `effects` from each start; the best result."""
    layout = _Layout(effects, problem.ts, problem.duration)

    def fun(vector: np.ndarray) -> np.ndarray:
        return problem.residual(effects, layout.to_params(vector))

    best: ModelFit | None = None
    for start in starts:
        x0 = layout.to_vector(start)
        # Stop when the cost changes by < 1e-6 relative: the likelihood ratio (n_eff ln of a
        # ratio of mean squares, n_eff <= 36000 for an hour at 10 Hz) moves by < 0.04, far
        # below the chi-square threshold of 10.8; half the evaluations of the default 1e-8.
        solution = optimize.least_squares(
            fun,
            x0,
            x_scale=layout.scale,
            method="lm",
            max_nfev=100 * (len(x0) + 1),
            ftol=1e-6,
            xtol=1e-6,
        )
        fit = problem.make_fit(effects, layout.to_params(solution.x))
        if best is None or fit.rmse < best.rmse:
            best = fit
    assert best is not None
    return best


def best_of(
    problem: Problem, effects: Sequence[str], trials: Sequence[Mapping[str, float]], keep: int
) -> list[Mapping[str, float]]:
    """The `keep` trial parameter sets with the smallest residual (cheap scan before a fit)."""
    scored = sorted(trials, key=lambda p: problem.sse(effects, p))
    return scored[:keep]

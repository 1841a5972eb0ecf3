"""estimation.reuse: steps kept by their arguments' content within a Kept block, and only there."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.estimation import tracking
from dualprobe.estimation.reuse import Kept, reused
from dualprobe.workflows import characterise as characterise_module
from dualprobe.workflows import order_choice
from dualprobe.workflows.characterise import characterise_arrays

calls: list[tuple[object, ...]] = []


@reused
def _step(x: np.ndarray, scale: float, *, shift: tuple[float, float] = (0.0, 0.0)
          ) -> tuple[np.ndarray, float]:
    calls.append((x, scale, shift))
    if scale < 0.0:
        raise ValueError("negative scale")
    return x * scale + shift[0], float(np.sum(x))


@pytest.fixture(autouse=True)
def _no_calls() -> None:
    calls.clear()


def test_outside_a_block_every_call_runs_and_returns_writable_arrays() -> None:
    x = np.arange(5.0)
    first, _ = _step(x, 2.0)
    second, _ = _step(x, 2.0)
    assert len(calls) == 2 and first is not second
    first[0] = 7.0  # a library call outside a characterisation keeps nothing: no side effect


def test_identical_content_is_run_once_and_returned_read_only() -> None:
    x = np.arange(5.0)
    with Kept() as kept:
        first = _step(x, 2.0, shift=(1.0, 0.0))
        # a copy with the same content is the same call
        second = _step(x.copy(), 2.0, shift=(1.0, 0.0))
        assert len(kept) == 1
    assert len(calls) == 1 and second is first
    assert not first[0].flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        first[0][0] = 0.0
    assert x.flags.writeable  # the caller's input is not touched
    np.testing.assert_array_equal(first[0], x * 2.0 + 1.0)


@pytest.mark.parametrize("change", ["sample", "dtype", "shape", "number", "keyword", "sequence"])
def test_any_change_in_content_runs_again(change: str) -> None:
    x = np.linspace(0.0, 1.0, 6)
    other = {"sample": (x + np.where(np.arange(6) == 3, 1e-15, 0.0), 2.0, (0.0, 0.0)),
             "dtype": (x.astype(np.float32), 2.0, (0.0, 0.0)),
             "shape": (x.reshape(2, 3), 2.0, (0.0, 0.0)),
             "number": (x, 2.0 + 1e-15, (0.0, 0.0)),
             "keyword": (x, 2.0, (0.0, 1e-300)),
             # a list is not taken for a tuple of the same numbers (a step may tell them apart)
             "sequence": (x, 2.0, [0.0, 0.0])}[change]
    with Kept():
        _step(x, 2.0, shift=(0.0, 0.0))
        _step(other[0], other[1], shift=other[2])
    assert len(calls) == 2


def test_failures_are_not_kept_and_unkeyable_arguments_run_every_time() -> None:
    x = np.arange(3.0)
    with Kept() as kept:
        for _ in range(2):
            with pytest.raises(ValueError, match="negative"):
                _step(x, -1.0)
        assert len(calls) == 2 and len(kept) == 0
        # an argument of no known content (an object) is never taken for another
        _step(x, 1.0, shift=(0.0, object()))  # type: ignore[arg-type]
        _step(x, 1.0, shift=(0.0, object()))  # type: ignore[arg-type]
    assert len(calls) == 4


def test_each_store_is_its_own_and_blocks_of_one_store_share() -> None:
    x = np.arange(4.0)
    one, two = Kept(), Kept()
    with one:
        _step(x, 3.0)
    with two:
        _step(x, 3.0)  # another characterisation: runs
    with one:
        _step(x, 3.0)  # the same one's second try (e.g. a first-order fallback): kept
        with two:
            _step(x, 3.0)  # nested: the inner store is the active one (kept there too)
        _step(x, 3.0)
    assert len(calls) == 2
    _step(x, 3.0)  # after the blocks nothing is active
    assert len(calls) == 3


def test_another_thread_does_not_see_the_block() -> None:
    x = np.arange(4.0)
    with Kept():
        _step(x, 5.0)
        worker = threading.Thread(target=_step, args=(x, 5.0))
        worker.start()
        worker.join()
    assert len(calls) == 2


def test_a_first_order_fallback_reuses_the_first_tries_steps_with_the_same_result(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Where evidence chooses the order and the second-order fit is refused, the first-order
    try repeats the order-independent steps (here the no-flow tracking of an unsheathed
    drive-cycle pair, its noise split and static search) on the same readings: they are
    taken from the first try, and the result is the one computed without reuse."""
    rng = np.random.default_rng(4)
    conditions = sim.drive_cycle(1200.0, rng)
    rec = sim.simulate_field_pair(
        conditions, sim.FieldSensor(4.0, 0.45, 0.0, noise_std=0.05),
        sim.FieldSensor(10.0, 0.45, 0.0, noise_std=0.05), sample_rate=10.0, quantisation=0.02,
        rng=rng)
    # the fallback forced (a second stage "not determined"), as a refused order-2 fit has it
    monkeypatch.setattr(order_choice, "undetermined_stages",
                        lambda estimate: [(0, 61.6, 1.68)])
    stores: list[Kept] = []

    class Spy(Kept):
        def __init__(self) -> None:
            super().__init__()
            self.depth = 0
            stores.append(self)

        def __enter__(self) -> Kept:
            self.depth += 1
            return super().__enter__()

        def __exit__(self, *exc: object) -> None:
            self.depth -= 1
            super().__exit__(*exc)

    class Never(Kept):
        """Keeps nothing: every step runs again (the reference)."""

        def __enter__(self) -> Kept:
            return self

        def __exit__(self, *exc: object) -> None:
            return None

    runs = {"calls": 0, "kept": 0, "repeats": 0}
    seen: set[tuple[object, ...]] = set()

    def content(value: object) -> object:
        # an argument's content, as a repeat is judged (arrays by their bytes)
        if isinstance(value, np.ndarray):
            return (value.dtype.str, value.shape, value.tobytes())
        if isinstance(value, tuple | list):
            return tuple(content(item) for item in value)
        return value

    def counted(step: Any) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:
            active = stores[-1] if stores and stores[-1].depth else None
            before = len(active) if active is not None else -1
            key = (step.__name__, content(args), content(sorted(kwargs.items())))
            runs["repeats"] += key in seen  # the same step with the same arguments again
            seen.add(key)
            out = step(*args, **kwargs)
            runs["calls"] += 1
            # answered from the store: it holds no new result after the call
            runs["kept"] += active is not None and len(active) == before
            return out
        return run

    for module, name in ((tracking, "track"), (tracking, "split_noise"),
                         (tracking, "search_static")):
        monkeypatch.setattr(module, name, counted(getattr(module, name)))

    results = {}
    for store in (Never, Spy):
        monkeypatch.setattr(characterise_module, "Kept", store)
        runs.update(calls=0, kept=0, repeats=0)
        seen.clear()
        results[store.__name__] = (characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t,
                                                       reconstruction=None), dict(runs))
    (reference, without), (result, with_store) = results["Never"], results["Spy"]
    assert "order_fallback" in result.estimate.identifiability
    model, expected = result.estimate.flow_model, reference.estimate.flow_model
    assert model is not None and expected is not None and model.kind == "tracked"
    # every call of the second try that repeats one of the first try's (the tracking, its
    # noise split and the two trackings inside it: 4) is answered from the store, and nothing
    # it spared runs (a kept noise split also spares the trackings inside it); the freer
    # trackings of the adaptation (estimation/adaptive.py) are not repeats: they take each
    # try's own filter setting (0.975 s in the first try here, 1.95 s in the fallback)
    ran = {name: runs["calls"] - runs["kept"] for name, runs in (("without", without),
                                                                 ("with", with_store))}
    assert without["kept"] == 0 and without["repeats"] >= 4, without
    assert with_store["kept"] == with_store["repeats"] >= 2, with_store
    assert ran["with"] == ran["without"] - without["repeats"], (ran, without)
    # the same result: not to the bit, since the same characterisation run twice in one process
    # differs by up to 2e-12 relative (measured: psi 1.9e-12, time constants 2e-14; summation
    # order with memory alignment), so to 1e-9, a thousand times less than any printed digit
    np.testing.assert_allclose(model.psi, expected.psi, rtol=1e-9, atol=0.0)
    np.testing.assert_allclose(np.concatenate(result.estimate.time_constants),
                               np.concatenate(reference.estimate.time_constants), rtol=1e-9)
    assert result.estimate.identifiability.keys() == reference.estimate.identifiability.keys()
    assert result.summary() == reference.summary()

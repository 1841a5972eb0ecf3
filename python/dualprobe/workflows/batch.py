"""`dualprobe batch`: characterise many recordings in parallel, one summary row per file, and
pool the flow-dependent time constants over all of them.

Each file goes through :func:`~dualprobe.workflows.characterise.characterise_file` in a worker
(:func:`characterise_one`, which never raises: a failure is a row with its error), locally in a
process pool (``concurrent.futures.ProcessPoolExecutor``, spawned workers) or, given a scheduler
address, on a Dask distributed cluster (``distributed.Client``). Outputs:

* ``DIR/summary.csv``: file, status (ok | warned: characterised, but the model check says the
  model does not explain the data or the data do not vouch for it, its reasons in ``warnings``
  | error: unusable input | inadequate: the data do not allow an estimate, exit 3 of
  `characterise`), the dominant time constant of each sensor with its std, the flow model's
  kind, exponent and its std, a quality figure (``rmse_vs_reference`` with a reference column,
  else the model check's ``misfit`` when the characterisation reports one), the wall time of the
  file in its worker, the loader's notes, the error message and the model check's warnings;
* ``DIR/pooled.json``: :func:`dualprobe.workflows.pool.pool_documents` over the files that
  are ok (a warned file's time constants are no calibration: listed under ``excluded`` with
  its reasons), plus the batch's bookkeeping (files, failures, wall times).
"""

from __future__ import annotations

import csv
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dualprobe.io import EstimationError, InputError
from dualprobe.report.json import write_json
from dualprobe.workflows.characterise import characterise_file
from dualprobe.workflows.pool import pool_documents, value

__all__ = ["SUMMARY_FIELDS", "BatchResult", "FileResult", "characterise_one", "run_batch"]

SUMMARY_FIELDS = (
    "file",
    "status",
    "tau1",
    "tau2",
    "tau1_std",
    "tau2_std",
    "flow_kind",
    "exponent",
    "exponent_std",
    "quality",
    "quality_kind",
    "wall_time_s",
    "notes",
    "error",
    "warnings",
)


@dataclass(frozen=True)
class FileResult:
    """One file's outcome: ``document`` is the characterisation's JSON document when ok or
    warned."""

    file: str
    status: str  # ok | warned | error | inadequate
    document: dict[str, Any] | None
    notes: tuple[str, ...]
    error: str | None
    wall_time: float
    warnings: tuple[str, ...] = ()

    def row(self) -> dict[str, Any]:
        doc = self.document or {}
        model = doc.get("flow_model") if isinstance(doc.get("flow_model"), Mapping) else {}
        quality, kind = value(doc, "reconstruction", "rmse_vs_reference"), "rmse_vs_reference"
        if not math.isfinite(quality):
            quality, kind = value(doc, "model_check", "misfit"), "model_check_misfit"
        exponent = model.get("exponent") if model else None
        exponent_std = model.get("exponent_std") if model else None
        return {
            "file": self.file,
            "status": self.status,
            "tau1": value(doc, "sensors", 0, "time_constants", 0),
            "tau2": value(doc, "sensors", 1, "time_constants", 0),
            "tau1_std": value(doc, "sensors", 0, "time_constants_std", 0),
            "tau2_std": value(doc, "sensors", 1, "time_constants_std", 0),
            "flow_kind": (model or {}).get("kind", ""),
            "exponent": _cell(exponent),
            "exponent_std": _cell(exponent_std),
            "quality": quality,
            "quality_kind": kind if math.isfinite(quality) else "",
            "wall_time_s": round(self.wall_time, 3),
            "notes": " | ".join(self.notes),
            "error": self.error or "",
            "warnings": " | ".join(self.warnings),
        }


def _cell(item: Any) -> Any:
    """A number, or per-sensor numbers joined by ';' (NaN when missing)."""
    if isinstance(item, (list, tuple)):
        return ";".join(f"{value([v], 0):.6g}" for v in item)
    return value([item], 0)


def _one_line(text: object) -> str:
    return " ".join(str(text).split()) or "(no message)"


def characterise_one(path: str, options: Mapping[str, Any]) -> FileResult:
    """Characterise one file; never raises (a failure is a result with its error)."""
    start = time.perf_counter()
    try:
        result = characterise_file(path, **dict(options))
        document = result.to_json_dict()
        check = result.model_check
        # never "ok" beside a model check that says otherwise (the summary line's warnings)
        warned = check is not None and not check.adequate
        warnings = tuple(_one_line(r) for r in check.reasons) if warned and check else ()
        return FileResult(path, "warned" if warned else "ok", document, tuple(result.notes),
                          None, time.perf_counter() - start, warnings)
    except InputError as exc:
        status, message = "error", _one_line(exc)
    except EstimationError as exc:
        status, message = "inadequate", _one_line(exc)
    except Exception as exc:  # a batch never stops on one file
        status, message = "error", f"internal: {type(exc).__name__}: {_one_line(exc)}"
    return FileResult(path, status, None, (), message, time.perf_counter() - start)


@dataclass(frozen=True)
class BatchResult:
    results: tuple[FileResult, ...]
    pooled: dict[str, Any]
    wall_time: float
    summary_path: Path
    pooled_path: Path
    workers: str = field(default="")

    @property
    def n_ok(self) -> int:
        return sum(1 for r in self.results if r.status == "ok")

    @property
    def n_warned(self) -> int:
        return sum(1 for r in self.results if r.status == "warned")

    def summary(self) -> str:
        failed = [r for r in self.results if r.status not in ("ok", "warned")]
        warned = [r for r in self.results if r.status == "warned"]
        times = [r.wall_time for r in self.results]
        counts = f"{self.n_ok} ok, " + (f"{len(warned)} warned (not pooled), " if warned else "")
        lines = [
            f"{len(self.results)} recordings ({self.workers}): {counts}"
            f"{len(failed)} failed; {self.wall_time:.1f} s in all, "
            f"{sum(times) / max(len(times), 1):.2f} s per recording in its worker",
        ]
        lines += [f"  warning: {r.file}: {r.warnings[0] if r.warnings else 'model check'}"
                  for r in warned[:10]]
        if len(warned) > 10:
            lines.append(f"  ... and {len(warned) - 10} more warned (see {self.summary_path})")
        lines += [
            f"  {r.status}: " + (r.error if (r.error or "").startswith(r.file)
                                 else f"{r.file}: {r.error}")
            for r in failed[:10]
        ]
        if len(failed) > 10:
            lines.append(f"  ... and {len(failed) - 10} more (see {self.summary_path})")
        for sensor in self.pooled.get("sensors", []):
            curve = sensor.get("curve")
            text = (
                f"sensor {sensor['sensor']} ({sensor.get('column')}): tau "
                f"{sensor['time_constant']:.5g} +/- {sensor['time_constant_std']:.2g} s"
            )
            if curve:
                text += (
                    f"; tau(flow) pooled over {curve['n_curves']} recordings, exponent "
                    f"{curve['exponent']:.4g} +/- {curve['exponent_std']:.2g}"
                )
            lines.append(text)
        lines.append(f"wrote {self.summary_path} and {self.pooled_path}")
        return "\n".join(lines)


def _local(
    files: Sequence[str], options: Mapping[str, Any], workers: int
) -> Iterator[FileResult]:
    if workers == 1:
        for path in files:
            yield characterise_one(path, options)
        return
    # spawn: workers that share nothing with a parent that may run threads (no fork hazards)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {pool.submit(characterise_one, path, options): path for path in files}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # a worker that died (killed, out of memory)
                yield FileResult(futures[future], "error", None, (),
                                 f"worker failed: {type(exc).__name__}: {_one_line(exc)}", 0.0)


def _dask(
    files: Sequence[str], options: Mapping[str, Any], scheduler: str
) -> Iterator[FileResult]:
    from distributed import Client
    from distributed import as_completed as dask_completed

    try:
        client = Client(scheduler, timeout="20s")
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: cannot connect ({_one_line(exc)})") from None
    with client:
        futures = {
            client.submit(characterise_one, path, dict(options), pure=False): path
            for path in files
        }
        for future in dask_completed(list(futures)):
            try:
                yield future.result()
            except Exception as exc:
                yield FileResult(futures[future], "error", None, (),
                                 f"worker failed: {type(exc).__name__}: {_one_line(exc)}", 0.0)


def _write_summary(path: Path, results: Sequence[FileResult]) -> None:
    try:
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=SUMMARY_FIELDS)
            writer.writeheader()
            for result in results:
                writer.writerow(result.row())
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None


def run_batch(
    files: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    options: Mapping[str, Any] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    on_result: Callable[[FileResult], None] | None = None,
) -> BatchResult:
    """Characterise ``files`` (keyword ``options`` of ``characterise_file``) and write
    ``out_dir/summary.csv`` and ``out_dir/pooled.json``.

    ``workers``: local processes (default: the CPU count; 1 runs in this process); ``scheduler``:
    a Dask distributed scheduler address (then ``workers`` is the cluster's business);
    ``progress``: a progress bar on stderr (default: when stderr is a terminal).

    Local workers are spawned (they import the package afresh), so a script calling this must
    do so under ``if __name__ == "__main__":`` (the ``dualprobe`` command does).
    """
    from tqdm import tqdm

    names = list(dict.fromkeys(str(f) for f in files))
    if not names:
        raise InputError("batch: no files given")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create ({exc.strerror or exc})") from None
    options = dict(options or {})
    if workers is not None and workers < 1:
        raise InputError(f"batch: workers must be >= 1, got {workers}")
    count = workers or os.cpu_count() or 1
    start = time.perf_counter()
    if scheduler:
        stream, label = _dask(names, options, scheduler), f"Dask scheduler {scheduler}"
    else:
        count = min(count, len(names))
        stream, label = _local(names, options, count), f"{count} local worker(s)"
    show = sys.stderr.isatty() if progress is None else progress
    found: dict[str, FileResult] = {}
    with tqdm(total=len(names), disable=not show, unit="file", file=sys.stderr) as bar:
        for result in stream:
            found[result.file] = result
            if on_result is not None:
                on_result(result)
            bar.update(1)
    results = tuple(found[name] for name in names)
    documents = [r.document for r in results if r.status == "ok" and r.document is not None]
    pooled = pool_documents(documents)
    pooled["files"] = [r.file for r in results if r.status == "ok"]
    pooled["failed"] = [{"file": r.file, "status": r.status, "error": r.error}
                        for r in results if r.status not in ("ok", "warned")]
    pooled["excluded"] = [{"file": r.file, "warnings": list(r.warnings)}
                          for r in results if r.status == "warned"]
    elapsed = time.perf_counter() - start
    pooled["wall_time_s"] = elapsed
    pooled["mean_wall_time_per_recording_s"] = sum(r.wall_time for r in results) / len(results)
    summary_path, pooled_path = out / "summary.csv", out / "pooled.json"
    _write_summary(summary_path, results)
    write_json(pooled, pooled_path)
    return BatchResult(results, pooled, elapsed, summary_path, pooled_path, label)

"""Writers of test recordings in every supported format (CSV, Parquet, MDF4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_csv(path: Path, columns: dict[str, np.ndarray], *, fmt: str = "%.10g") -> Path:
    table = np.column_stack([np.asarray(v, dtype=float) for v in columns.values()])
    np.savetxt(path, table, delimiter=",", header=",".join(columns), comments="", fmt=fmt)
    return path


def write_parquet(path: Path, columns: dict[str, np.ndarray]) -> Path:
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({name: np.asarray(v) for name, v in columns.items()}), path)
    return path


def write_mdf(
    path: Path,
    groups: list[tuple[np.ndarray, dict[str, np.ndarray]]],
    units: dict[str, str] | None = None,
    invalid: dict[str, np.ndarray] | None = None,
) -> Path:
    """One channel group per (time stamps, {channel: samples}) entry; ``invalid``: a channel's
    invalidation bits (True: the sample is invalid)."""
    from asammdf import MDF, Signal

    units = units or {}
    invalid = invalid or {}
    mdf = MDF(version="4.10")
    try:
        for stamps, channels in groups:
            signals = [
                Signal(np.asarray(v, dtype=float), np.asarray(stamps, dtype=float), name=name,
                       unit=units.get(name, ""), invalidation_bits=invalid.get(name))
                for name, v in channels.items()
            ]
            mdf.append(signals)
        mdf.save(path, overwrite=True)
    finally:
        mdf.close()
    return path

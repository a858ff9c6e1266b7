"""The summary of a batch: ``summary.csv`` streamed row by row (a manifest of any length
is never held in memory as results), ``summary.parquet`` converted from it in batches,
and the optional ``summary.png``."""

from __future__ import annotations

import csv
import typing
from collections.abc import Iterable, Iterator
from dataclasses import fields
from pathlib import Path

from ...figures import plot_batch
from ...io import atomic_write
from .items import ItemResult

__all__ = ["COLUMNS", "write_summary", "read_summary"]

COLUMNS = tuple(f.name for f in fields(ItemResult))
_TYPES = {f.name: typing.get_type_hints(ItemResult)[f.name] for f in fields(ItemResult)}
_FLOAT_COLUMNS = ("distance", "tolerance", "frame_distance", "energy", "strain_min",
                  "strain_max", "seconds")


def write_summary(results: Iterable[ItemResult], out, *, figure: bool = False) -> list[Path]:
    """Write ``out/summary.csv``, ``summary.parquet`` (when pyarrow is installed) and,
    with ``figure``, ``summary.png``; each file atomically. ``results`` are consumed one
    at a time. Returns the paths written."""
    out = Path(out)
    written = [out / "summary.csv"]
    with atomic_write(written[0]) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(COLUMNS)
        writer.writerows(["" if (v := getattr(row, c)) is None else v for c in COLUMNS]
                        for row in results)
    parquet = _write_parquet(written[0], out / "summary.parquet")
    if parquet is not None:
        written.append(parquet)
    if figure:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6.4, 4.4))  # no pyplot: no figure left open
        plot_batch(list(read_summary(out)), ax=fig.add_subplot())
        written.append(out / "summary.png")
        with atomic_write(written[-1]) as tmp:
            fig.savefig(tmp, dpi=150, bbox_inches="tight")
    return written


def _write_parquet(source: Path, path: Path) -> Path | None:
    """``summary.csv`` as Parquet, converted a block at a time (None without pyarrow)."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq
    except ImportError:
        return None
    types = {"steps": pa.int64(), "converged": pa.bool_()}
    schema = pa.schema([(c, types.get(c, pa.float64() if c in _FLOAT_COLUMNS
                                      else pa.string())) for c in COLUMNS])
    reader = pacsv.open_csv(source, convert_options=pacsv.ConvertOptions(
        column_types=schema, strings_can_be_null=False, quoted_strings_can_be_null=False))
    with atomic_write(path) as tmp, pq.ParquetWriter(tmp, schema) as writer:
        for block in reader:
            writer.write_batch(block)
    return path


def read_summary(out) -> Iterator[ItemResult]:
    """The rows of ``out/summary.csv``, one at a time, typed as :class:`ItemResult`."""
    with open(Path(out) / "summary.csv", newline="", encoding="utf-8") as fh:
        for record in csv.DictReader(fh):
            yield ItemResult(**{k: _value(v, _TYPES[k]) for k, v in record.items()})


def _value(text: str, kind) -> object:
    if kind is str:
        return text
    if text == "":
        return None
    if kind == int | None:
        return int(text)
    if kind == bool | None:
        return text == "True"
    return float(text)

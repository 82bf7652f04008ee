"""A sweep's results: one row per point, the grid keys as columns, the JSON the command printed flattened
(``error_ms.p95``), and the row's own columns; written as ``results.parquet`` and ``results.csv``.

=============  =======================================================================================
column         what
=============  =======================================================================================
grid keys      the point's values (a named axis by its name)
metrics        every number, string or flag of the JSON, nested keys joined by dots (``rate.min``);
               a list as its JSON text; a JSON list of objects by index (``0.error_ms.p95``); a name
               that is also a grid key or a row column gets ``result.`` in front (``result.strategy``)
``status``     ``ok`` or ``failed``
``error``      why it failed (empty when ok)
``seconds``    how long the command ran on its worker
``worker``     the worker that ran it
``point``      the point's cache key (``points/<point>.json``)
``command``    the command line that computes the point alone
=============  =======================================================================================
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from agentsim.written import written
from agentsim.cli.sweep.spec import ROW_COLUMNS, Point, shell_line
from agentsim.errors import Unavailable

#: Prefix of a metric whose name is taken by a grid key or a row column.
TAKEN_PREFIX = "result."


def flatten(value, prefix: str = "") -> dict:
    """Nested JSON as one level of dotted keys (lists of scalars as JSON text)."""
    flat = {}
    if isinstance(value, dict):
        for key, item in value.items():
            flat.update(flatten(item, f"{prefix}{key}."))
    elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        for index, item in enumerate(value):
            flat.update(flatten(item, f"{prefix}{index}."))
    elif isinstance(value, list):
        flat[prefix[:-1]] = json.dumps(value)
    else:
        flat[prefix[:-1] or "value"] = value
    return flat


def metric_columns(result, grid_keys) -> dict:
    """The metric columns of one point's JSON."""
    taken = set(grid_keys) | set(ROW_COLUMNS)
    return {(TAKEN_PREFIX + k if k in taken else k): v for k, v in flatten(result).items()}


def make_row(point: Point, outcome: dict) -> dict:
    """The row of a point from what :func:`agentsim.cli.sweep.point.run_point` returned (or the cache kept)."""
    row = dict(point.values)
    row.update(status=outcome["status"], error=outcome.get("error"))
    if outcome.get("result") is not None:
        row.update(metric_columns(outcome["result"], point.values))
    row.update(seconds=outcome.get("seconds"), worker=outcome.get("worker"), attempts=outcome.get("attempts"),
               point=point.key,
               command=shell_line(point.argv))
    return row


def frame(rows: list[dict], grid_keys, plan: "Plan | None" = None):
    """The rows as a pandas DataFrame: grid keys, status and error first, then the metrics, then the rest; a
    column of values of several types (but numbers) as their text, one of whole and decimal numbers as decimal
    numbers. ``plan``: the columns and their types as they are in all the rows, of which ``rows`` are some."""
    pd = pandas()
    if plan is not None:
        table = pd.DataFrame(rows, columns=plan.columns, dtype=object)
        for column in plan.columns:
            if column not in plan.conversions:
                table[column] = table[column].astype(plan.types[column])
        return converted(table, plan.conversions)
    columns = list(grid_keys) + ["status", "error"]
    for row in rows:
        columns += [c for c in row if c not in columns and c not in ROW_COLUMNS]
    columns += [c for c in ROW_COLUMNS if c not in columns]
    table = pd.DataFrame(rows, columns=columns)
    return converted(table, conversions(table))


def conversions(table) -> dict[str, str]:
    """The columns of ``table`` that parquet could not take as they are (it wants one type a column): those of
    values of several types but numbers (``"text"``), and those of whole and decimal numbers (``"float"``)."""
    found = {}
    for column in table.columns:
        if table[column].dtype == object:
            kinds = {type(v) for v in table[column] if v is not None and not (isinstance(v, float) and math.isnan(v))}
            if len(kinds) > 1 and not kinds <= {int, float}:
                found[column] = "text"
            elif kinds <= {int, float} and kinds:
                found[column] = "float"
    return found


def converted(table, conversions: dict[str, str]):
    for column, how in conversions.items():
        table[column] = ([None if v is None else str(v) for v in table[column]] if how == "text"
                         else table[column].astype(float))
    return table


class Plan:
    """The columns of a sweep's rows and the type of each, learnt one row at a time without keeping the rows:
    their order as :func:`frame` gives it, and of each column a few values that stand for all of them (one of
    each type, the smallest and largest whole number, a NaN, a row without it); :func:`frame` of these few rows
    gives every column the type it gives it from all the rows (pandas infers a column's type from the types
    of its values, whatever their number)."""

    def __init__(self, grid_keys):
        self.grid_keys = list(grid_keys)
        self.columns = self.grid_keys + ["status", "error"]
        self.known = set(self.columns)
        self.samples: dict[str, dict] = {}
        self.present: dict[str, int] = {}
        self.rows = self.failed = 0
        self.types: dict = {}
        self.conversions: dict[str, str] = {}
        self.schema = None

    def add(self, row: dict) -> None:
        self.rows += 1
        self.failed += row.get("status") != "ok"
        for column, value in row.items():
            if column not in self.known and column not in ROW_COLUMNS:
                self.columns.append(column)
                self.known.add(column)
            self.present[column] = self.present.get(column, 0) + 1
            samples = self.samples.setdefault(column, {})
            if type(value) is int:
                samples["low"] = min(samples.get("low", value), value)
                samples["high"] = max(samples.get("high", value), value)
            elif isinstance(value, float) and math.isnan(value):  # a missing value to pandas
                samples.setdefault("nan", value)
            else:
                samples.setdefault(type(value), value)

    def finish(self) -> "Plan":
        """The columns in their final order, the type :func:`frame` gives each, and the parquet schema."""
        import pyarrow as pa

        self.columns += [c for c in ROW_COLUMNS if c not in self.known]
        absent = object()
        stand_ins = {c: list(self.samples.get(c, {}).values()) + ([absent] if self.present.get(c, 0) < self.rows
                                                                  else []) for c in self.columns}
        length = max([len(values) for values in stand_ins.values()] + [1])
        rows = [{c: values[min(i, len(values) - 1)] for c, values in stand_ins.items()
                 if values and values[min(i, len(values) - 1)] is not absent} for i in range(length)]
        probe = pandas().DataFrame(rows, columns=self.columns)
        self.conversions = conversions(probe)
        probe = converted(probe, self.conversions)
        self.types = dict(probe.dtypes)
        self.schema = pa.Schema.from_pandas(probe, preserve_index=False)
        return self


#: How many rows are made, and written, at a time: the results of a grid of any size cost the memory of this
#: many rows.
BATCH_ROWS = 10_000


def write_rows(rows, grid_keys, folder: Path) -> tuple[Path, Path, Plan]:
    """``results.parquet`` and ``results.csv`` in ``folder`` from ``rows()`` (called twice: it gives the rows
    anew each time), each written whole or not at all, :data:`BATCH_ROWS` rows at a time: the same tables as
    :func:`write` of :func:`frame` of all the rows, without holding them."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    plan = Plan(grid_keys)
    for row in rows():
        plan.add(row)
    plan.finish()
    parquet, csv = folder / "results.parquet", folder / "results.csv"
    with written(parquet) as parquet_tmp, written(csv) as csv_tmp, open(csv_tmp, "w", newline="") as text, \
            pq.ParquetWriter(parquet_tmp, plan.schema) as writer:
        for batch in batches(rows(), BATCH_ROWS, plan):
            writer.write_table(pa.Table.from_pandas(batch, preserve_index=False).cast(plan.schema))
            batch.to_csv(text, index=False, header=text.tell() == 0)
    return parquet, csv, plan


def batches(rows, size: int, plan: Plan):
    """The rows as frames of ``size`` rows (one frame, of no row, if there are none)."""
    batch, sent = [], False
    for row in rows:
        batch.append(row)
        if len(batch) == size:
            yield frame(batch, plan.grid_keys, plan)
            batch, sent = [], True
    if batch or not sent:
        yield frame(batch, plan.grid_keys, plan)


def write(table, folder: Path) -> tuple[Path, Path]:
    """``results.parquet`` and ``results.csv`` in ``folder``, each written whole or not at all."""
    parquet, csv = folder / "results.parquet", folder / "results.csv"
    for path, save in ((parquet, lambda p: table.to_parquet(p, index=False)),
                       (csv, lambda p: table.to_csv(p, index=False))):
        with written(path) as tmp:
            save(tmp)
    return parquet, csv


def read(folder: Path):
    """The results table of a sweep folder (parquet; the CSV if there is no parquet)."""
    pd = pandas()
    if (folder / "results.parquet").is_file():
        return pd.read_parquet(folder / "results.parquet")
    return pd.read_csv(folder / "results.csv")


def pandas():
    try:
        import pandas as pd
        import pyarrow  # noqa: F401  (parquet)
    except ImportError as exc:
        raise Unavailable(f"the sweep's results need pandas and pyarrow ({exc.name} is missing): "
                          "pip install pandas pyarrow") from None
    return pd

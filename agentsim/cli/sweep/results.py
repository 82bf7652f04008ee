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


def frame(rows: list[dict], grid_keys):
    """The rows as a pandas DataFrame: grid keys, status and error first, then the metrics, then the rest."""
    pd = pandas()
    columns = list(grid_keys) + ["status", "error"]
    for row in rows:
        columns += [c for c in row if c not in columns and c not in ROW_COLUMNS]
    columns += [c for c in ROW_COLUMNS if c not in columns]
    table = pd.DataFrame(rows, columns=columns)
    for column in table.columns:
        if table[column].dtype == object:  # parquet wants one type a column
            kinds = {type(v) for v in table[column] if v is not None and not (isinstance(v, float) and math.isnan(v))}
            if len(kinds) > 1 and not kinds <= {int, float}:
                table[column] = [None if v is None else str(v) for v in table[column]]
            elif kinds <= {int, float} and kinds:
                table[column] = table[column].astype(float)
    return table


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

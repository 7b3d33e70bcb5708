"""``manifest.csv``: one row per finished sample of a dataset build, for a person or pandas to read.

Columns, in order: ``index``, ``split``, ``seed``; every drawn value under its dotted key (sorted;
a sample that did not draw a key leaves it empty); ``fraction.<label name>`` for each declared
label, background first (the share of the sample's voxels with that label); in a build whose samples
have instance volumes, last, ``instance_table``: the file, relative to the build, of the sample's
instance id → yarn table (a JSON object too large for a cell: a sample has tens to hundreds of
yarns), empty for a sample without. No wall times: the same build gives the same bytes (a build
logs its times instead). Strings are
written as they are, other values as JSON (numbers in their shortest exact form, lists as
``[1, 2]``, booleans ``true``/``false``); a missing value is empty.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..core.errors import ConfigError
from ..core.files import atomic_write_text

FIXED_COLUMNS = ("index", "split", "seed")
INSTANCE_TABLE_COLUMN = "instance_table"


def flat_values(values: dict, prefix: str = "") -> dict:
    """``values`` with nested mappings flattened to dotted keys (``{"a": {"b": 1}}`` → ``{"a.b": 1}``)."""
    flat = {}
    for key, value in values.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flat_values(value, f"{dotted}."))
        else:
            flat[dotted] = value
    return flat


def json_ready(value):
    """``json.dumps``'s ``default``: NumPy scalars and arrays as Python numbers and lists."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def cell(value) -> str:
    """A value as its manifest cell (module docstring)."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    return json.dumps(value, default=json_ready)


def manifest_text(records: dict[int, dict], label_names: dict[int, str], instance_tables=None) -> str:
    """The CSV of ``records`` (index → the record a layout stored, with ``split``, ``seed``,
    ``values`` and ``fractions`` by label value), one row per index in order, the
    fraction columns named by ``label_names`` (label value → name, 0 included);
    ``instance_tables``: index → the file of its instance table, for the samples that have one (the
    column only where some do)."""
    values = {index: flat_values(record.get("values", {})) for index, record in records.items()}
    drawn = sorted({key for flat in values.values() for key in flat})
    fractions = [f"fraction.{label_names[label]}" for label in sorted(label_names)]
    tables = [INSTANCE_TABLE_COLUMN] if instance_tables else []
    clash = sorted(set(drawn) & {*FIXED_COLUMNS, *fractions, *tables})
    if clash:
        raise ConfigError(f"a drawn value's key {clash[0]!r} is also a column of manifest.csv; rename the key")
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow([*FIXED_COLUMNS, *drawn, *fractions, *tables])
    for index in sorted(records):
        record = records[index]
        shares = record.get("fractions", {})
        writer.writerow([index, cell(record.get("split")), cell(record.get("seed")),
                         *(cell(values[index].get(key)) for key in drawn),
                         *(cell(shares.get(str(label), 0.0)) for label in sorted(label_names)),
                         *(cell(instance_tables.get(index)) for _ in tables)])
    return out.getvalue()


def write_manifest(path, records: dict[int, dict], label_names: dict[int, str], instance_tables=None) -> Path:
    """Write :func:`manifest_text` to ``path`` atomically."""
    return atomic_write_text(path, manifest_text(records, label_names, instance_tables))

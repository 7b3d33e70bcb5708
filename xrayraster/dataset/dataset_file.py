"""Dataset files (TOML): a base scan, the dataset's settings and the scan-file keys to vary (docs/dataset.md).

``xrayraster build`` makes ``count`` labelled tomograms, sample ``i`` being ``xr.scan`` of the scan
table :func:`draw` makes for ``i``. A draw depends on the master ``seed`` and ``i`` only: sample
``i`` is the same whether drawn alone or in a loop, in any process, and whatever ``count`` is, so
a dataset grows by raising ``count`` and a build resumes sample by sample.

Seeds: sample ``i``'s first attempt draws from ``SeedSequence(seed, spawn_key=(i,))``, attempt
``a`` > 0 from ``SeedSequence(seed, spawn_key=(i, a))``; each ``[vary]`` key draws from its own
child of the attempt's sequence (tagged by a hash of the key), so adding or removing a key
leaves the other keys' draws as they were. The split and the sample's integer seed come from
children of the first attempt's sequence, so a redraw changes neither.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import fields
from ..core.choices import DATASET_KEEP, DATASET_LAYOUTS, DATASET_SPLITS
from ..core.errors import ConfigError, GeometryError, WeaveError
from ..core.validate import show
from ..io.scan_file import SCAN_TABLES, ScanFile, load_scan_file
from ..io.scan_keys import ANY, INDEX, KEYS, absolute_paths, check_key, set_key, value_at
from ..io.scene_file import read_toml
from .distributions import KINDS, Distribution, Fixed, distribution_from, is_distribution, resolved_around
from .layouts import NAME_RULE, check_name

__all__ = ["DATASET_KEYS", "DatasetFile", "Draw", "differences", "draw", "fingerprint", "identity", "is_dataset_table",
           "load_dataset_file", "refuse_dataset_table"]

#: Attempts at a sample before its draws are called impossible: a draw that a scan file cannot
#: hold (yarns wider than their spacing) is redrawn from the next derived seed.
MAX_ATTEMPTS = 20
#: Indices stay below 2**31, so the tags of the keys' streams (top bit set) never equal an attempt.
MAX_COUNT = 2 ** 31
#: The keys of the ``[dataset]`` table.
DATASET_KEYS = {"count", "seed", "layout", "splits", "name", "keep"}
#: What only a dataset file holds: a scan (or scene) file with one of these is a dataset file.
DATASET_ONLY = ("dataset", "vary", "base")
_SPLIT_TOLERANCE = 1e-9
# Seeds a sample gets from its own seed unless [vary] names them (or a table above them).
_SEED_KEYS = ("scan.seed", "weave.sample.seed")


@dataclass(frozen=True)
class DatasetFile:
    """A loaded dataset file. ``base``: the base scan's table, its relative file paths made absolute
    against the base scan file's directory; ``splits``: split name → fraction, in
    :data:`~xrayraster.core.choices.DATASET_SPLITS` order; ``vary``: dotted scan-file key → its
    :mod:`~xrayraster.dataset.distributions` distribution; ``directory``: what relative file paths
    among ``[vary]``'s values are relative to (the dataset file's directory, or ``base_dir``)."""

    path: Path | None
    base: dict
    count: int
    seed: int
    layout: str
    splits: dict
    name: str
    keep: tuple[str, ...]
    vary: dict
    directory: Path

    @property
    def where(self) -> str:
        """The file as error messages name it."""
        return str(self.path) if self.path is not None else "dataset table"


@dataclass(frozen=True)
class Draw:
    """Sample ``index`` of a dataset: ``seed`` (its integer seed, the default of ``scan.seed`` and
    ``weave.sample.seed``), ``values`` (dotted key → drawn value, JSON-ready), ``split``, the
    ``attempts`` it took and the ``redraws`` (one line per impossible draw), ``table`` (the full scan
    table, JSON- and TOML-ready) and ``scan``, that table loaded (not compared, not in the repr)."""

    index: int
    seed: int
    values: dict
    split: str
    attempts: int
    redraws: tuple[str, ...]
    table: dict
    scan: ScanFile = field(compare=False, repr=False)


def load_dataset_file(source, *, base_dir=None) -> DatasetFile:
    """Read and check a dataset file, or the dict of one already parsed (then ``base = "..."`` and
    the relative paths of ``[vary]``'s values are relative to ``base_dir``, default the current
    directory). Every key is checked and sample 0 drawn before it returns, so a bad file fails
    before any work: ConfigError, one line naming the file, the table and the key."""
    if isinstance(source, Mapping):
        path, data, where = None, source, "dataset table"
        directory = Path(base_dir if base_dir is not None else ".").absolute()
    else:
        # Absolute and normalised: the samples' metadata names the file, the same however it was spelt.
        path = Path(os.path.abspath(source))
        data, where, directory = read_toml(path, "dataset file"), str(path), path.parent
    fields.only(data, {"base", "dataset", "vary", *SCAN_TABLES}, where)
    base = _base(data, directory, where, path)
    settings = fields.table(fields.required(data, "dataset", where), "dataset", where)
    dataset = DatasetFile(path, base, vary=_vary(fields.table(data.get("vary", {}), "vary", where), base, where),
                          directory=directory, **_settings(settings, path, f"{where} [dataset]"))
    draw(dataset, 0)
    return dataset


def draw(dataset: DatasetFile, index: int) -> Draw:
    """Sample ``index``'s scan table, drawn from (``dataset.seed``, ``index``) alone (module docstring)
    and loaded; an impossible table (the scan file loader refuses it) is redrawn, up to
    :data:`MAX_ATTEMPTS` times, else ConfigError naming the ``[vary]`` keys and the last reason."""
    fields.integer(index, "index", f"{dataset.where} sample", 0, MAX_COUNT - 1)
    first = np.random.SeedSequence(dataset.seed, spawn_key=(index,))
    seed = int(_child(first, "seed").generate_state(1, np.uint32)[0])
    split = _split(dataset.splits, np.random.default_rng(_child(first, "split")).random())
    where = f"{dataset.where} sample {index}"
    failed: dict[str, str] = {}  # drawn values → why they fail: an attempt that draws them again fails alike
    reasons: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        sequence = first if attempt == 0 else np.random.SeedSequence(dataset.seed, spawn_key=(index, attempt))
        values = {key: d.sample(np.random.default_rng(_child(sequence, key))) for key, d in dataset.vary.items()}
        table = drawn_table(dataset, values, seed)
        known = _canonical(values)
        if known not in failed:
            try:
                scan = load_scan_file(table, where=where, base_dir=dataset.directory)
            except (ConfigError, WeaveError, GeometryError) as exc:
                failed[known] = " ".join(str(exc).split())  # one line for the log
            else:
                redraws = tuple(f"attempt {a + 1}: {reason}" for a, reason in enumerate(reasons))
                return Draw(index, seed, values, split, attempt + 1, redraws, table, scan)
        reasons.append(failed[known])
    varied = ", ".join(k for k, d in dataset.vary.items() if not isinstance(d, Fixed)) or "none"
    raise ConfigError(f"{dataset.where} [vary]: sample {index}: none of {MAX_ATTEMPTS} draws makes a scan file "
                      f"(varied: {varied}); the last: {reasons[-1]}")


def drawn_table(dataset: DatasetFile, values: dict, seed: int) -> dict:
    """The base scan table with ``values`` (dotted key → value) set, and ``seed`` as ``scan.seed`` and
    ``weave.sample.seed`` where ``[vary]`` names neither the key nor a table above it."""
    table = copy.deepcopy(dataset.base)
    for key, value in values.items():
        set_key(table, key, copy.deepcopy(value))
    for key in _SEED_KEYS:
        parts = key.split(".")
        varied = any(".".join(parts[:n]) in dataset.vary for n in range(1, len(parts) + 1))
        if not varied and parts[0] in table:
            set_key(table, key, seed)
    return absolute_paths(table, dataset.directory)


def fingerprint(dataset: DatasetFile) -> str:
    """sha256 (hex) of the canonical JSON of everything that decides the samples but ``count``, so a
    build can refuse a changed dataset file against its existing samples (and grow with ``count``)."""
    return hashlib.sha256(_canonical(identity(dataset)).encode()).hexdigest()


def differences(a: DatasetFile | dict, b: DatasetFile | dict) -> list[str]:
    """What changed from ``a`` to ``b`` (datasets, or their :func:`identity`, as a build records it)
    among what :func:`fingerprint` hashes, one line per key (``seed: 1 -> 2``, ``base
    weave.sample.cells: [2, 2] -> [3, 3]``, ``vary source.kvp: absent -> ...``)."""
    # Through JSON, as a record holds it: tuples and lists, ints and floats then compare alike.
    old, new = (_flat(json.loads(_canonical(d if isinstance(d, dict) else identity(d)))) for d in (a, b))
    return [f"{key}: {_show(old, key)} -> {_show(new, key)}" for key in sorted(old.keys() | new.keys())
            if old.get(key, _ABSENT) != new.get(key, _ABSENT)]


# ----------------------------------------------------------------------------- reading


def _base(data: dict, directory: Path, where: str, own: Path | None) -> dict:
    """The base scan table: the file ``base`` names or the inline tables, its file paths made absolute.
    ``own``: the dataset file's path (None for a table), which ``base`` may not name."""
    inline = {k: v for k, v in data.items() if k in SCAN_TABLES}
    if "base" in data:
        if inline:
            raise ConfigError(f"{where}: give the base scan as base = \"scan.toml\" or as inline tables, not both "
                              f"(got base and [{'], ['.join(sorted(inline))}]); remove one")
        path = directory / fields.string(data["base"], "base", where)
        table = read_toml(path, "scan file")
        if own is not None and path.resolve() == own.resolve():
            raise ConfigError(f"{where}: base = {show(data['base'])} names this dataset file itself; base names the "
                              "scan file every sample starts from (docs/scan.md), or give its tables inline")
        refuse_dataset_table(table, f"{where}: base = {show(data['base'])}", "a scan file (docs/scan.md)")
        fields.only(table, SCAN_TABLES, str(path))
        return absolute_paths(table, path.parent.absolute())
    if not inline:
        raise ConfigError(f"{where}: no base scan; add base = \"twin_small.toml\" (a scan file, relative to this "
                          "file) or the scan's tables inline ([weave] or [[objects]], [source], ...)")
    return absolute_paths(copy.deepcopy(inline), directory)


def is_dataset_table(data) -> bool:
    """Whether a parsed TOML file is a dataset file (it holds [dataset], [vary] or base)."""
    return isinstance(data, Mapping) and any(key in data for key in DATASET_ONLY)


def refuse_dataset_table(data, where: str, expected: str) -> None:
    """Refuse a dataset file where ``expected`` (a scan file, a scene file) is read: one line naming
    what it is, instead of its keys as unknown ones. ``where`` names the file as the reader says it.
    (For a loader of scan or scene files: ``xrayraster preview DATASET.toml`` meets this too.)"""
    if is_dataset_table(data):
        found = ", ".join(f"[{k}]" if k != "base" else "base" for k in DATASET_ONLY if k in data)
        raise ConfigError(f"{where} is a dataset file (it has {found}: docs/dataset.md), not {expected}; give "
                          "a scan file, or build the dataset with `xrayraster build DATASET.toml -o DIR`")


def _settings(d: dict, path: Path | None, where: str) -> dict:
    """The ``[dataset]`` table's keys, checked, with their defaults."""
    fields.only(d, DATASET_KEYS, where)
    layout = fields.choice(d.get("layout", DATASET_LAYOUTS[0]), "layout", where, DATASET_LAYOUTS)
    return {"count": fields.integer(fields.required(d, "count", where), "count", where, 1, MAX_COUNT),
            "seed": fields.integer(fields.required(d, "seed", where), "seed", where, 0),
            "layout": layout, "splits": _splits(d.get("splits", {"train": 1.0}), where), "name": _name(d, path, where),
            "keep": _keep(d.get("keep", []), where)}


def _name(d: dict, path: Path | None, where: str) -> str:
    """``[dataset] name``, or by default the file's name, other characters as ``_``; refused unless
    it is a dataset name (layouts.check_name: the one rule of every layout)."""
    if "name" in d:
        return check_name(fields.string(d["name"], "name", where), where)
    default = re.sub(r"[^A-Za-z0-9_]", "_", path.stem) if path is not None else "dataset"
    try:
        return check_name(default, where)
    except ConfigError:
        suggestion = default.strip("_") or "dataset"
        raise ConfigError(f"{where}: the dataset's name defaults to the file's, {default!r}, which is not "
                          f"{NAME_RULE}; set name = \"{suggestion}\" in [dataset]") from None


def _splits(value, where: str) -> dict:
    table = fields.table(value, "splits", where)
    fields.only(table, set(DATASET_SPLITS), f"{where} splits")
    splits = {k: fields.number(table[k], f"splits.{k}", where, nonnegative=True) for k in DATASET_SPLITS if k in table}
    total = sum(splits.values())
    if abs(total - 1) > _SPLIT_TOLERANCE:
        raise ConfigError(f"{where}: splits must sum to 1, got {total:.12g} ({show(value)}); "
                          "give fractions such as { train = 0.8, val = 0.1, test = 0.1 }")
    return splits


def _keep(value, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or any(k not in DATASET_KEEP for k in value) or len(set(value)) != len(value):
        raise ConfigError(f"{where}: keep must be an array of distinct names from {', '.join(DATASET_KEEP)}, "
                          f"got {show(value)}")
    return tuple(k for k in DATASET_KEEP if k in value)


def _vary(table: dict, base: dict, where: str) -> dict[str, Distribution]:
    """``[vary]``, its nested tables flattened to dotted keys, each key checked and read."""
    where = f"{where} [vary]"
    flat = _flatten(table, "", where)
    for key in flat:
        check_key(key, base, where)
        inside = [other for other in flat if key.startswith(other + ".")]
        if inside:
            raise ConfigError(f"{where}: '{key}' lies inside '{inside[0]}', which is varied too; vary one of them")
    return {key: distribution_from(resolved_around(value, key, value_at(base, key), where), key, where)
            for key, value in flat.items()}


def _flatten(table: dict, prefix: str, where: str) -> dict:
    flat = {}
    for name, value in table.items():
        key = f"{prefix}{name}"
        if isinstance(value, dict) and not is_distribution(value):
            if _names_a_value(key):  # a table where a value goes: meant as a distribution, of no known kind
                raise ConfigError(f"{where}: '{key}' = {show(value)}: unknown distribution "
                                  f"{', '.join(repr(k) for k in value)}; give one of {', '.join(KINDS)} "
                                  "(docs/dataset.md), or a value; a table as the value is { choice = [{ ... }] }")
            if not value:
                raise ConfigError(f"{where}: '{key}' is an empty table: give a distribution such as "
                                  "{ uniform = [a, b] }, a value, or keys below it")
            entries = _flatten(value, key + ".", where)
        else:
            entries = {key: value}
        for k in entries:
            if k in flat:
                raise ConfigError(f"{where}: '{k}' is given twice (as a dotted key and in a nested table); keep one")
        flat.update(entries)
    return flat


def _names_a_value(key: str) -> bool:
    """Whether the dotted scan-file ``key`` names a value (a leaf of scan_keys.KEYS), not a table."""
    tree = KEYS
    for part in key.split("."):
        if not isinstance(tree, dict):
            return False  # below a value, or in a table the key sets do not describe
        if INDEX in tree:
            tree = tree[INDEX] if part.isdigit() else _MISSING
        else:
            tree = tree.get(part, tree.get(ANY, _MISSING))
    return tree is None


_MISSING = object()


# ----------------------------------------------------------------------------- drawing


def _child(sequence: np.random.SeedSequence, name: str) -> np.random.SeedSequence:
    """The stream of ``name`` under ``sequence``: a tag from a hash of the name, top bit set so that
    it never equals an index or an attempt (both below 2**31)."""
    tag = 0x80000000 | int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "big")
    return np.random.SeedSequence(sequence.entropy, spawn_key=(*sequence.spawn_key, tag))


def _split(splits: dict, u: float) -> str:
    """The split whose share of the cumulative fractions holds ``u`` (uniform in [0, 1))."""
    total = 0.0
    for name, fraction in splits.items():
        total += fraction
        if u < total:
            return name
    return [name for name, fraction in splits.items() if fraction > 0][-1]  # u above a sum just under 1


# ----------------------------------------------------------------------------- identity

_ABSENT = object()


def identity(dataset: DatasetFile) -> dict:
    """Everything that decides the samples but ``count``, JSON-ready: what :func:`fingerprint` hashes
    and a build's record keeps, so a later run can say what changed."""
    return {"base": dataset.base, "seed": dataset.seed, "layout": dataset.layout, "splits": dataset.splits,
            "name": dataset.name, "keep": list(dataset.keep),
            "vary": {key: d.to_dict() for key, d in dataset.vary.items()}}


def _canonical(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, default=str)


def _flat(ident: dict) -> dict:
    """Dotted names for :func:`differences`: the base scan's keys, each ``[vary]`` key whole, the rest."""
    flat = {f"vary {key}": value for key, value in ident["vary"].items()}
    flat.update({key: value for key, value in ident.items() if key not in ("base", "vary")})

    def walk(value, prefix):
        if isinstance(value, dict) and value:
            for k, v in value.items():
                walk(v, f"{prefix}.{k}" if prefix else k)
        else:
            flat[f"base {prefix}"] = value

    walk(ident["base"], "")
    return flat


def _show(flat: dict, key: str) -> str:
    return "absent" if key not in flat else _canonical(flat[key])

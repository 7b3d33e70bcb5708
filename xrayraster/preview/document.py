"""The file a preview shows: a scene, scan or weave file as its TOML tables, edited key by key
(dotted keys, as a dataset's ``[vary]`` names them: ``source.kvp``, ``weave.sample.seed``), checked
by the file's own loader, and written back as a TOML file that ``xrayraster render`` (a scene
file) or ``xrayraster scan`` and ``build`` (a scan file) take unchanged. A weave file is previewed
as the scan file it makes with ``xrayraster weave``'s tube (``DEFAULT_SOURCE``), and saved as one.

The view options that are not keys of the file (the angle, what is shown, the noise of a scene
file's radiograph) live in :class:`View`; a saved file carries the angle as its first view, so
view 0 of the saved file is the view on screen.
"""

from __future__ import annotations

import copy
import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import tomli_w

from ..core import fields
from ..core.choices import RADIOGRAPH_OUTPUTS
from ..core.errors import ConfigError
from ..dataset.dataset_file import refuse_dataset_table
from ..io.scan_file import load_scan_file
from ..io.scan_keys import INDEX, PATH_KEYS, absolute_paths, check_key, set_key
from ..io.scene_file import load_scene_file, read_toml
from ..io.weave_file import DEFAULT_SOURCE

#: Tables only a scan file has: a file with none of them is a scene file (``xrayraster render``'s).
SCAN_TABLES = {"weave", "volume", "scan", "pose", "mount"}
#: Tables that leave the sample as it is: a change below them meshes or uploads nothing again.
SCANNER_TABLES = ("geometry", "source", "detector")
#: What a frame shows: a radiograph quantity, or the path length (mm) through one material.
OUTPUTS = (*RADIOGRAPH_OUTPUTS, "path_length")
#: The range of a TOML integer (64 bits; JSON has no limit), and more levels than any value an edit
#: may give nests (the whole [materials] table: a material's mass fractions are three levels down).
TOML_INTEGERS = (-2**63, 2**63 - 1)
MAX_NESTING = 8
#: The keys that name files (mesh and spectrum files), as a message shows them.
FILE_KEYS = ", ".join(".".join("N" if part == INDEX else part for part in key) for key in PATH_KEYS)


@dataclass(frozen=True)
class View:
    """What the preview shows of a document: ``angle_deg`` (the first view's angle, degrees; None:
    the file's own), ``output`` (one of :data:`OUTPUTS`), ``material`` (the channel a path-length
    frame shows), photon ``noise`` and its ``seed`` (a scan file's ``[scan]`` keys when it is one)."""

    angle_deg: float | None = None
    output: str = "lineint"
    material: int = 0
    noise: bool = False
    seed: int = 0

    @classmethod
    def from_dict(cls, d: dict) -> "View":
        """The view a page asks for; ConfigError naming the field when a value is unusable or not of
        its JSON type (``"noise": "yes"`` is no boolean)."""
        fields.only(d, {f.name for f in dataclasses.fields(cls)}, "view")
        angle = d.get("angle_deg")
        return cls(angle_deg=None if angle is None else fields.number(angle, "angle_deg", "view"),
                   output=fields.choice(d.get("output", "lineint"), "output", "view", OUTPUTS),
                   material=fields.integer(d.get("material", 0), "material", "view", 0),
                   noise=fields.boolean(d.get("noise", False), "noise", "view"),
                   seed=fields.integer(d.get("seed", 0), "seed", "view", 0))


@dataclass(frozen=True, eq=False)
class Document:
    """A scene or scan file's tables (``kind`` "scene" or "scan"), with file paths made absolute so
    the tables load, and save, from anywhere. Never changed in place: :meth:`edited` makes another."""

    path: Path
    kind: str
    table: dict

    @classmethod
    def open(cls, path) -> "Document":
        path = Path(path)
        data = read_toml(path, "scene, scan or weave file")
        refuse_dataset_table(data, str(path), "a scene, scan or weave file")
        if "weave" in data and set(data) <= {"weave", "materials"}:
            # A weave file is a scan file without a tube: the scan of `xrayraster weave`'s scene file
            # (its framing geometry is a scan file's default for a weave), which saving makes a scan file.
            data["source"] = dict(DEFAULT_SOURCE)
        kind = "scan" if SCAN_TABLES & set(data) else "scene"
        table = absolute_paths(data, path.resolve().parent)
        loaded = cls(path, kind, table).load()  # a bad file fails before a server starts
        if "geometry" not in table:
            # A weave's scan frames the sample by default; the preview's scanner stays where it was
            # framed when the sample changes, as a real one does, and its keys can be edited and saved.
            table = {**table, "geometry": loaded.geometry.to_dict()}
        return cls(path, kind, table)

    def load(self, objects_of=None):
        """The file as its loader reads it (``SceneFile`` or ``ScanFile``); ConfigError naming the key.
        ``objects_of``: a scene file's load with the same objects and materials, reused as it is."""
        base = self.path.resolve().parent
        if self.kind == "scan":
            return load_scan_file(self.table, where=str(self.path), base_dir=base)
        return load_scene_file(self.table, where=str(self.path), base_dir=base, objects_of=objects_of)

    def sample_key(self) -> str:
        """The tables below the sample (all but the scanner's :data:`SCANNER_TABLES`), as one string:
        while it is unchanged, the scene the projections see is the same."""
        return json.dumps({k: v for k, v in self.table.items() if k not in SCANNER_TABLES}, sort_keys=True)

    def edited(self, edits: dict) -> "Document":
        """This document with ``edits`` ({dotted key: value}, a value of None removing the key)
        applied; the keys are checked here, the values by :meth:`load`. An edit changes values, never
        which files are read: a key that names a file, or a table or array that holds one, is refused
        (the page serves one file and what it names, whatever a request asks)."""
        table = copy.deepcopy(self.table)
        for key, value in edits.items():
            if names_files(key):
                raise ConfigError(f"{self.path}: '{key}' cannot be edited in a preview: which files are read "
                                  f"({FILE_KEYS}, and the tables and arrays that hold them) is fixed when the file "
                                  f"opens; change it in {self.path.name} itself and open that again")
            check_key(key, table, f"{self.path}")
            toml_value(value, key, f"{self.path}")
            if value is None:
                *parents, last = key.split(".")
                holder = table
                for part in parents:
                    holder = holder.get(part, {}) if isinstance(holder, dict) else {}
                if isinstance(holder, dict):
                    holder.pop(last, None)
            else:
                set_key(table, key, value)
        return Document(self.path, self.kind, table)

    def initial_view(self, loaded=None) -> View:
        """The view a page opens with: a scan file's own noise and seed (its scan's defaults).
        ``loaded``: the file as :meth:`load` reads it, when at hand."""
        if self.kind == "scan":
            options = (loaded or self.load()).options
            return View(noise=options.noise, seed=options.seed)
        return View()

    def saved(self, view: View) -> dict:
        """The tables to save for ``view``: its angle as the first view's (``start_angle_deg``, or
        the ``angles_deg`` turned with it) and, for a scan file, its noise and seed."""
        table = copy.deepcopy(self.table)
        geometry = table["geometry"]
        if view.angle_deg is not None and "vectors" not in geometry:
            if "angles_deg" in geometry:
                geometry["angles_deg"] = turned_angles(geometry["angles_deg"], view.angle_deg)
            else:
                geometry["start_angle_deg"] = view.angle_deg
        if self.kind == "scan":
            table.setdefault("scan", {}).update(noise=view.noise, seed=view.seed)
        return table

    def settings(self, view: View, name: str, loaded=None) -> str:
        """The text of the file saved as ``name`` for ``view`` (:meth:`saved`, headed by the command
        that renders it), read by the file's loader first, as a frame is: a file that command would
        refuse is never saved (ConfigError naming the key). ``loaded``: this document as :meth:`load`
        reads it (a scene file's meshes are not read again)."""
        table = self.saved(view)
        Document(self.path, self.kind, table).load(objects_of=loaded)
        return (f"# Saved by xrayraster preview; view 0 is the view on screen:\n# {self.command(name, view)}\n"
                + tomli_w.dumps(table))

    def command(self, name: str, view: View) -> str:
        """The command line that renders view 0 of the file saved as ``name`` as the preview shows it."""
        if self.kind == "scan":
            return f"xrayraster scan {name} -o scan"
        if view.output == "path_length":
            return f"xrayraster render {name} -o view.tif --path-lengths"
        noise = f" --noise --seed {view.seed}" if view.noise else ""
        return f"xrayraster render {name} -o view.tif --output {view.output}{noise}"


def turned_angles(angles, first: float) -> list[float]:
    """``angles`` turned so the first is ``first`` (exactly) and the others keep their spacing from
    it: ``first + (a - angles[0])``, in whatever unit they are given (a file's degrees, a geometry's
    radians). The one turn of the preview: a saved file's ``angles_deg`` and a frame's geometry."""
    start = angles[0]
    return [first + (a - start) for a in angles]


def names_files(key: str) -> bool:
    """Whether the dotted ``key`` is a file key (:data:`PATH_KEYS`) or a table or array above one:
    ``objects.0.mesh``, ``objects.0``, ``objects``, ``source``. A key below a mesh (a primitive's
    ``objects.1.mesh.sphere``) is not: a table stays a table. Any part stands for an array's index,
    as ``check_key`` reads ``00`` or other digits as one."""
    parts = key.split(".")
    return any(len(parts) <= len(path) and all(want in (INDEX, part) for want, part in zip(path, parts))
               for path in PATH_KEYS)


def toml_value(value, key: str, where: str) -> None:
    """Refuse an edit's value that no TOML file holds, before a loader's checks meet it: an integer
    beyond 64 bits (they would overflow converting it), a null below the top (None at the top
    removes the key), or arrays and tables nested beyond any file's (a hostile request's)."""
    pending = [(value, 0)]
    while pending:  # not recursive: a value nested a thousand deep must not exhaust the stack
        item, depth = pending.pop()
        if depth > MAX_NESTING:
            raise ConfigError(f"{where}: '{key}': nested deeper than any value of the file ({MAX_NESTING} levels)")
        if isinstance(item, dict):
            pending.extend((v, depth + 1) for v in item.values())
        elif isinstance(item, list):
            pending.extend((v, depth + 1) for v in item)
        elif item is None and depth > 0:
            raise ConfigError(f"{where}: '{key}': null is no TOML value; give a number, string, array or table")
        elif isinstance(item, int) and not isinstance(item, bool) and not TOML_INTEGERS[0] <= item <= TOML_INTEGERS[1]:
            raise ConfigError(f"{where}: '{key}': an integer beyond 64 bits, which no TOML file holds; give a "
                              "smaller one, or a float")

"""A build's directory, before and after its samples: what it holds checked before the build
writes (an earlier build's record, files a person left, write permission), the build recorded
(``build.json``), an earlier build's samples removed (``--force``: its files only), and the
temporaries a killed build left swept away."""

from __future__ import annotations

import json
from pathlib import Path

from ..core.errors import ConfigError
from ..core.files import atomic_write_text, directory_target, probe_writable, remove_entry, remove_stale_temporaries_in
from ..core.ownership import directory_entries, read_record
from ..core.provenance import package_version
from .dataset_file import DatasetFile, differences, fingerprint, identity
from .layouts import LAYOUTS
from .names import FAILED_NAME, GALLERY_NAME, GENERATOR, RECORD_NAME


def sweep(root: Path) -> None:
    """Remove the stale temporaries (their writers gone) in ``root`` and its visible folders: a
    layout writes its samples' temporaries there (``samples/.00007.…``, ``imagesTr/.…``), never
    deeper, as a sample's own folder appears whole."""
    for folder in _folders(root):
        remove_stale_temporaries_in(folder)


def checked_directory(dataset: DatasetFile, directory, force: bool) -> tuple[Path, dict | None]:
    """The dataset directory (links resolved) and, when this run replaces the earlier build there
    (``force``, and a changed dataset file), that build's record; refused otherwise as the module
    docstring says. Nothing is written."""
    path = Path(directory)
    root = directory_target(path, GENERATOR)
    if not (root.is_dir() and any(root.iterdir())):
        _check_writable(root, path)
        return root, None
    earlier = read_record(root / RECORD_NAME, GENERATOR)
    if earlier is None:
        raise ConfigError(f"{path} holds files that {GENERATOR} did not write (no {RECORD_NAME}); they are never "
                          "removed: choose another directory")
    changed = differences(earlier["identity"], dataset) if earlier["fingerprint"] != fingerprint(dataset) else []
    if earlier["count"] > dataset.count:
        changed.append(f"count: {earlier['count']} -> {dataset.count} (a build only grows)")
    if changed and not force:
        raise ConfigError(f"{path} holds a build of another dataset file ({'; '.join(changed)}); rerun with the "
                          "same file (count may grow), choose another directory, or pass --force to remove this "
                          "build's samples and start again")
    _check_writable(root, path)
    return root, earlier if changed else None


def record_build(root: Path, dataset: DatasetFile, replaced: dict | None) -> None:
    """Remove the build ``replaced`` names, if any (its index first, so that no manifest lists a
    sample that is gone), then record this one's dataset file in ``build.json``."""
    if replaced is not None:
        earlier = LAYOUTS[replaced["identity"]["layout"]]
        for name in [*earlier.index_names(), GALLERY_NAME, FAILED_NAME]:
            (root / name).unlink(missing_ok=True)
        _remove_samples(root, replaced["identity"])
    root.mkdir(parents=True, exist_ok=True)
    record = {"generator": GENERATOR, "version": package_version(), "fingerprint": fingerprint(dataset),
              "count": dataset.count, "identity": identity(dataset)}
    atomic_write_text(root / RECORD_NAME, json.dumps(record, indent=2, sort_keys=True) + "\n")


def check_sample_folders(root: Path, layout, todo: list[int], name: str) -> None:
    """Refuse a folder a sample left writes whole (``samples/00003``) that holds files the build did
    not write: they would fail that sample, and are never removed."""
    for index in todo:
        for folder, marker in layout.sample_folders(index, name):
            if (root / folder).is_dir():
                foreign = directory_entries(root / folder, marker, GENERATOR)[1]
                if foreign:
                    shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
                    raise ConfigError(f"{root / folder} holds {shown}, which {GENERATOR} did not write, where sample "
                                      f"{index} goes; they are never removed: move them out of that folder, or "
                                      "choose another directory")


def _check_writable(root: Path, path: Path) -> None:
    """Refuse (ConfigError naming ``path``) an existing build directory, or a folder in it the build
    writes into (samples/, imagesTr/, ...), that cannot be written: immutable, read-only, another
    user's. Found now, not sample by sample."""
    if root.is_dir():
        for folder in _folders(root):
            probe_writable(folder, path)


def _folders(root: Path) -> list[Path]:
    """``root`` and its visible folders: where a layout writes its samples, never deeper."""
    return [root, *(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))]


def _remove_samples(root: Path, earlier: dict) -> None:
    """Remove the samples of an earlier build (``earlier``: its identity): the files its layout
    names (their extra labels' too), those its samples' folders record (kept projections, meshes)
    and the folders they leave empty, nothing else (a person's files stay)."""
    layout = LAYOUTS[earlier["layout"]]
    folders = set()
    for index, record in layout.finished(root, earlier["name"]).items():
        for folder, marker in layout.sample_folders(index, earlier["name"]):
            if (root / folder).is_dir():
                for entry in directory_entries(root / folder, marker, GENERATOR)[0]:  # the recorded ones
                    remove_entry(root / folder / entry)
            folders.add(root / folder)
        for relative in layout.sample_paths(index, record["split"], earlier["name"], record.get("extra_labels", ())):
            remove_entry(root / relative)
            folders.update((root / relative).parents)
    for folder in sorted(folders - set(root.parents) - {root}, key=lambda f: -len(f.parts)):  # deepest first
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()

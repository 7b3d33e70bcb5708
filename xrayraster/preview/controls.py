"""The controls a page shows for a document: one per file key the preview lets a user change, with
its current value (the file's, or the loader's default where the file leaves it out), unit and a
sensible range for the slider. The page sends changes back as ``{key: value}`` edits; the file's
loader, not the slider's range, decides what is valid (a typed value outside the range is tried,
and refused with the loader's message when it is wrong)."""

from __future__ import annotations

from ..core.choices import SCATTER_MODELS
from ..weave.families import FAMILIES, FAMILY_FIELDS
from .document import Document

# key, label, unit, kind ("number" or "integer"), slider min, max, step
_SCANNER = (
    ("geometry.source_to_origin", "source to axis", "mm", "number", 1.0, 2000.0, 0.5),
    ("geometry.source_to_detector", "source to detector", "mm", "number", 2.0, 4000.0, 0.5),
    ("source.kvp", "tube voltage", "kV", "number", 10.0, 300.0, 0.5),
    ("source.mas", "exposure", "mAs", "number", 0.01, 100.0, 0.01),
    ("source.focal_spot_mm", "focal spot", "mm", "number", 0.0, 1.0, 0.001),
    ("detector.blur_sigma_px", "detector blur σ", "px", "number", 0.0, 5.0, 0.05),
    ("detector.gain_variation", "gain variation (rings)", "share", "number", 0.0, 0.1, 0.001),
)
# key, label, the choices: a list to pick from
_CHOICES = (
    ("physics.scatter", "scatter", SCATTER_MODELS),
)
_WEAVE = (
    ("weave.sample.seed", "distortion seed", "", "integer", 0, 100000, 1),
    ("weave.weft_spacing", "weft spacing", "mm", "number", 0.5, 10.0, 0.05),
    ("weave.warp_spacing", "warp spacing", "mm", "number", 0.5, 10.0, 0.05),
    ("weave.thickness", "thickness", "mm", "number", 0.5, 20.0, 0.05),
    ("weave.weft_per_layer", "wefts per layer", "", "integer", 1, 16, 1),
    ("weave.weft_layers", "weft layers", "", "integer", 2, 12, 1),
    ("weave.warp_ratio", "stuffer columns a group", "", "integer", 1, 8, 1),
    ("weave.binder_ratio", "binder positions a group", "", "integer", 1, 8, 1),
    ("weave.binder_step", "columns a binder gap", "", "integer", 1, 8, 1),
    ("weave.binder_offset", "binder offset", "columns", "integer", 0, 16, 1),
    ("weave.plies", "plies", "", "integer", 1, 16, 1),
    ("weave.harness", "satin harness", "wefts", "integer", 5, 16, 1),
)


def controls(document: Document, loaded) -> list[dict]:
    """The page's controls for ``document`` as ``loaded`` reads it (``SceneFile`` or ``ScanFile``)."""
    out = []
    table = document.table
    for key, label, unit, kind, lo, hi, step in _SCANNER:
        section, name = key.split(".")
        if section == "geometry" and loaded.geometry.beam != "cone":
            continue
        if section == "source" and name in ("kvp", "mas") and "kvp" not in table.get("source", {}):
            continue  # a monochromatic or tabulated source has no tube
        value = table.get(section, {}).get(name, _default(loaded, key))
        out.append(_control(key, label, unit, kind, lo, hi, step, value))
    for key, label, choices in _CHOICES:
        section, name = key.split(".")
        out.append({"key": key, "label": label, "unit": "", "kind": "choice", "choices": list(choices),
                    "value": table.get(section, {}).get(name, _default(loaded, key))})
    filters = table.get("source", {}).get("filters", {}) if "kvp" in table.get("source", {}) else None
    for material in (filters or ({"Al": 0.0} if filters is not None else {})):
        out.append(_control(f"source.filters.{material}", f"{material} filter", "mm", "number", 0.0, 10.0, 0.05,
                            filters.get(material, 0.0)))
    if document.kind == "scan" and loaded.weave is not None:
        sample = loaded.weave.sample
        family = FAMILIES[sample.cell.family]
        for key, label, unit, kind, lo, hi, step in _WEAVE:
            name = key.split(".")[-1]
            if ((name in FAMILY_FIELDS and name not in family.takes) or (name == "warp_ratio" and not sample.cell.stuffers)
                    or (name == "weft_per_layer" and family.plies)):
                continue  # a field of another family, a ratio of stuffers the cell has not, or a ply's pattern's
            value = sample.seed if name == "seed" else getattr(sample.cell, name)
            if name == "harness" and value is None:
                value = len(sample.cell.pattern)  # the satin's own
            out.append(_control(key, label, unit, kind, lo, hi, step, value))
    return out


def _default(loaded, key: str):
    """The value the loader uses for a scanner key the file leaves out."""
    realism, detector = loaded.realism, loaded.detector
    return {
        "geometry.source_to_origin": getattr(loaded.geometry, "source_to_origin", None),
        "geometry.source_to_detector": getattr(loaded.geometry, "source_to_detector", None),
        "source.focal_spot_mm": realism.focal_spot_mm,
        "source.mas": 1.0,
        "detector.blur_sigma_px": 0.0 if detector is None else detector.blur_sigma_px,
        "detector.gain_variation": realism.gain_variation,
        "physics.scatter": realism.scatter,
    }.get(key)


def _control(key, label, unit, kind, lo, hi, step, value) -> dict:
    return {"key": key, "label": label, "unit": unit, "kind": kind, "min": lo, "max": hi, "step": step,
            "value": value}

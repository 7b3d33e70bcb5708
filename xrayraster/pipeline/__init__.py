"""One-command scans: a scan file → projections → FDK → labels (docs/scan.md), the metrics
that compare a scan with another (docs/compare.md), woven samples from a weave file (docs/weave.md), and
dataset files, their deterministic draws of scan files, and dataset builds (docs/dataset.md).

The orchestration layer: it may import every stage and no stage imports it; it runs without the
command line (``xr.scan``, ``xr.weave``), which stays a thin layer on top (``xrayraster scan``, ``xrayraster weave``).
"""

from .compare import Comparison, compare
from .dataset import BuildReport, build
from .dataset_file import DatasetFile, Draw, differences, draw, fingerprint, load_dataset_file
from .dataset_plan import format_plan, plan_rows
from .scan import ScanResult, check_scan_output, scan
from .scan_file import ScanFile, ScanOptions, load_scan_file
from .woven import WeaveResult, weave

__all__ = [
    "BuildReport", "Comparison", "DatasetFile", "Draw", "ScanFile", "ScanOptions", "ScanResult", "WeaveResult", "build", "compare",
    "check_scan_output", "differences", "draw", "fingerprint", "format_plan", "load_dataset_file", "load_scan_file",
    "plan_rows", "scan", "weave",
]

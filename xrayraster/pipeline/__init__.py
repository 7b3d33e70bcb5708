"""One-command scans: a scan file → projections → FDK → labels (docs/scan.md), the metrics
that compare a scan with another (docs/compare.md), and woven samples from a weave file (docs/weave.md).

The orchestration layer: it may import every stage and no stage imports it; it runs without the
command line (``xr.scan``, ``xr.weave``), which stays a thin layer on top (``xrayraster scan``, ``xrayraster weave``).
"""

from .compare import Comparison, compare
from .scan import ScanResult, check_scan_output, scan
from .scan_file import ScanFile, ScanOptions, load_scan_file
from .woven import WeaveResult, weave

__all__ = [
    "Comparison", "ScanFile", "ScanOptions", "ScanResult", "WeaveResult", "compare", "check_scan_output", "load_scan_file",
    "scan", "weave",
]

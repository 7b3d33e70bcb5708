"""One-command scans: a scan file → projections → FDK → labels (docs/scan.md), the metrics
that compare a scan with another (docs/compare.md), a scan file fitted to a real scan (docs/fit.md), and
woven samples from a weave file (docs/weave.md).
Dataset builds, which run many scans, are the layer above (``xrayraster.dataset``).

The orchestration layer: it may import every stage below it, and only the dataset builds above
import it. It runs without the command line (``xr.scan``, ``xr.weave``), which stays a thin layer on
top (``xrayraster scan``, ``xrayraster weave``).
"""

from ..io.scan_file import ScanFile, ScanOptions, load_scan_file
from .compare import Comparison, compare
from .fit import FitResult, fit
from .scan import ScanResult, check_scan_output, scan
from .woven import WeaveResult, weave

__all__ = [
    "Comparison", "FitResult", "ScanFile", "ScanOptions", "ScanResult", "WeaveResult", "check_scan_output", "compare",
    "fit", "load_scan_file", "scan", "weave",
]

"""Ctrl-C and SIGTERM at any moment of ``xrayraster scan``, start-up included: exit 130 (143 for
SIGTERM) with one line on stderr, no traceback, and nothing left beside the output directory; once
the scan has finished (the process shutting down), exit 0 with the outputs in place.

The runs are sequential (the machine may have two cores) and each is cut short, about 15 s in all.
``--quiet`` keeps the progress bar off stderr, so stderr holds only the command's own lines.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "twin_small.toml"
VIEWS = 600  # instead of its 120, so that the scan runs past the last signal (2-3 s at 120 views, start-up included)


def _console_script() -> list[str]:
    """The installed ``xrayraster`` script (what users run), else ``python -m xrayraster``."""
    beside = Path(sys.executable).parent / "xrayraster"
    return [str(beside)] if beside.exists() else [sys.executable, "-m", "xrayraster"]


def _scan_cut_short(tmp_path: Path, signum: int, after_s: float) -> tuple[int | None, str]:
    """Start the scan, send ``signum`` ``after_s`` seconds in; (exit status, stderr), or (None, stderr)
    when the process had ended before the signal (a fast machine)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "out" / "scan"
    out.parent.mkdir()  # made here so that it can be checked for leftovers whenever the signal comes
    scan_file = tmp_path / "scan.toml"
    text = EXAMPLE.read_text()
    assert "num_views = 120" in text
    scan_file.write_text(text.replace("num_views = 120", f"num_views = {VIEWS}"))
    proc = subprocess.Popen([*_console_script(), "scan", str(scan_file), "-o", str(out), "--quiet"], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    time.sleep(after_s)
    finished = proc.poll() is not None
    if not finished:
        proc.send_signal(signum)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"still running 60 s after the signal; stderr: {err}")
    return (None if finished else proc.returncode), err


@pytest.mark.parametrize("signum, after_s, status", [
    (signal.SIGINT, 0.2, 130), (signal.SIGINT, 0.5, 130), (signal.SIGINT, 1.0, 130), (signal.SIGINT, 2.0, 130),
    (signal.SIGINT, 3.0, 130), (signal.SIGTERM, 2.0, 143),
], ids=["int-0.2s", "int-0.5s", "int-1s", "int-2s", "int-3s", "term-2s"])
def test_a_signal_at_any_moment_exits_in_one_line_and_leaves_nothing(tmp_path, signum, after_s, status):
    returncode, err = _scan_cut_short(tmp_path, signum, after_s)
    if returncode is None:
        shutil.rmtree(tmp_path / "out")
        pytest.skip(f"the scan finished within {after_s} s, before the signal")
    if returncode == 0:  # the signal came after the scan had finished, as the process shut down: ignored
        assert err == "" and (tmp_path / "out" / "scan" / "volume.tif").is_file()
        pytest.skip(f"the scan finished within {after_s} s, before the signal")
    assert returncode == status, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert err.count("\n") == 1 and err.startswith("xrayraster: "), err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [], "left behind"


SWALLOWED = """
import os, signal, time
from xrayraster.cli import interrupts

class Dropping:
    def __del__(self):  # an interrupt raised in here is printed as "Exception ignored" and dropped
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)

interrupts.install()
try:
    if "{case}" == "bare-except":
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)
        except BaseException:
            pass
    else:
        Dropping()
    time.sleep(0.5)
    print("lost")
except KeyboardInterrupt:
    interrupts.handled()
    print("delivered again")
"""


@pytest.mark.parametrize("case", ["bare-except", "in-__del__"])
def test_a_dropped_interrupt_is_delivered_again_without_a_message(case):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", SWALLOWED.format(case=case)], env=env, capture_output=True, text=True,
                         timeout=60)
    assert (run.returncode, run.stdout, run.stderr) == (0, "delivered again\n", "")


@pytest.mark.parametrize("code", ["import xrayraster", "import xrayraster.weave", "import xrayraster.cli"])
def test_importing_the_package_loads_no_heavy_library(code):
    """What the command line imports before it handles signals: its names load on first use."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    check = f"{code}; import sys; print(sorted({{'numpy', 'trimesh', 'spekpy', 'pyopencl'}} & set(sys.modules)))"
    run = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stdout) == (0, "[]\n"), run.stderr

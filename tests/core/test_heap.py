"""core/heap.py: freed arrays reused without the kernel faulting their pages in again, checked by
the kernel's own count of a process's page faults."""

import os
import platform
import subprocess
import sys

import pytest

from xrayraster.core.heap import USER_VARIABLES

pytestmark = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the settings are glibc's mallopt")

# 50 rounds of two 8 MiB arrays made, written and freed: their pages fault in every round when the
# blocks are mmap'd and unmapped (fewer faults than pages where the kernel maps huge pages), and
# only in the first when the heap keeps them.
CHILD = """
import resource, sys
import numpy as np
from xrayraster.core.heap import keep_freed_memory
applied = keep_freed_memory() if sys.argv[1] == "keep" else None
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    a = np.ones(1 << 20)
    b = a * 2.0
    del a, b
print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""
ROUNDS_ARRAYS = 50 * 2


def _faults(mode: str, **env) -> tuple[str, int]:
    clean = {k: v for k, v in os.environ.items() if k not in USER_VARIABLES}
    done = subprocess.run([sys.executable, "-c", CHILD, mode], env={**clean, **env}, capture_output=True, text=True,
                          check=True)
    applied, faults = done.stdout.split()
    return applied, int(faults)


def test_freed_arrays_are_reused_without_page_faults():
    default = _faults("default")[1]
    assert default > 4 * ROUNDS_ARRAYS  # glibc's default unmaps them: the test can fail
    applied, faults = _faults("keep")
    assert applied == "True"
    assert faults < default / 20


def test_a_users_own_malloc_setting_is_left_alone():
    applied, faults = _faults("keep", MALLOC_TRIM_THRESHOLD_="1")
    assert applied == "False"
    assert faults > 4 * ROUNDS_ARRAYS


def test_the_command_line_and_the_build_workers_keep_freed_memory(monkeypatch):
    """Both entry points that own their process call it (a library import does not)."""
    import xrayraster.cli as cli
    from xrayraster.dataset import build

    calls = []
    monkeypatch.setattr(cli, "keep_freed_memory", lambda: calls.append("cli"))
    with pytest.raises(SystemExit):
        cli.main(["scan", "--help"])
    monkeypatch.setattr("xrayraster.core.heap.keep_freed_memory", lambda: calls.append("worker"))
    monkeypatch.setattr(build, "_contexts", None)
    monkeypatch.setattr("xrayraster.gl.context.GLContext", lambda: "gl")
    monkeypatch.setattr("xrayraster.recon.opencl.CLContext", lambda: "cl")
    assert build._worker_contexts(None) == ("gl", "cl")
    assert calls == ["cli", "worker"]


HAND_BACK = """
import os
import numpy as np
from xrayraster.core.heap import hand_back_freed_memory, keep_freed_memory

def resident_mib():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

keep_freed_memory()
arrays = [np.ones(1 << 17) for _ in range(64)]  # 64 arrays of 1 MiB, from the heap
held = resident_mib()
del arrays
kept = resident_mib()
hand_back_freed_memory()
print(held, kept, resident_mib())
"""


def test_a_worker_hands_the_kept_memory_back_between_samples():
    """64 MiB freed stay resident under keep_freed_memory (below its 128 MiB threshold) until
    hand_back_freed_memory returns them to the kernel."""
    clean = {k: v for k, v in os.environ.items() if k not in USER_VARIABLES}
    done = subprocess.run([sys.executable, "-c", HAND_BACK], env=clean, capture_output=True, text=True, check=True)
    held, kept, handed_back = map(float, done.stdout.split())
    assert held - kept < 8  # the test can fail: the freed arrays are kept
    assert kept - handed_back > 56


"""The C heap of a process that scans: freed arrays kept for the next ones instead of handed back.

A scan makes and drops arrays of 1–30 MiB many times a second: a view's read-back and physics
(a 512² float64 image is 2 MiB), the FDK's filtered chunks. glibc's malloc serves blocks of that
size with ``mmap`` and unmaps them when freed (its threshold follows the largest block freed, but
it trims its heap as soon as twice that lies free at its top), so each new array faults its pages
in again from the kernel, zeroed: 512 faults for 2 MiB. Measured on 2 vCPUs (AMD EPYC), a twin
view's physics on one thread, 300 views: 15 ms a view, 2.4 s of it in the kernel, against 6.4–7.2
ms and 0.03–0.06 s with the settings below; the peak memory was the same (58 MiB). The cost is
that a process keeps up to :data:`TRIM_THRESHOLD_BYTES` of freed heap in each of its malloc arenas
(glibc makes one for each thread that allocates, up to 8 a core), which suits a command or a dataset
worker but not a library imported into someone's process, so only those call
:func:`keep_freed_memory`, and a dataset worker hands the kept memory back after each sample
(:func:`hand_back_freed_memory`).
"""

from __future__ import annotations

import ctypes
import functools
import os
import platform

# glibc's mallopt parameters (malloc.h) and the values set.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 << 20  # blocks below it come from the heap: glibc's largest on 64 bits
TRIM_THRESHOLD_BYTES = 128 << 20  # free memory at the heap's top kept up to this
# glibc's own variables for the same: a user who set one has chosen, and is left alone.
USER_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")


@functools.cache
def _glibc() -> bool:
    return platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"


@functools.cache
def keep_freed_memory() -> bool:
    """Keep freed blocks below 32 MiB in this process's heap for reuse (module docstring). Returns
    whether the settings were applied: not where the C library is not glibc, nor where the user set
    glibc's own variables. Once per process; later calls return the first answer."""
    if not _glibc():
        return False
    if any(name in os.environ for name in USER_VARIABLES):
        return False
    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD,
                                                                                 TRIM_THRESHOLD_BYTES))


def hand_back_freed_memory() -> None:
    """Return the free pages of every malloc arena to the kernel (glibc's ``malloc_trim``). A dataset
    worker calls it between samples: what :func:`keep_freed_memory` keeps pays within a sample's
    thousands of arrays, not across samples, and a worker's resident memory then is what it holds.
    Measured on 2 vCPUs, 100 tiny samples in one worker: 441–458 MiB resident without it, wandering
    with the arenas' free memory, 380–385 MiB with it, at the same seconds a sample. A no-op where
    the C library is not glibc."""
    if _glibc():
        ctypes.CDLL(None).malloc_trim(0)

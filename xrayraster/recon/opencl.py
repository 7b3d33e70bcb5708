"""The OpenCL context: one object owns the device, its queue and the compiled kernels of ``shaders/``.

Device choice, in order:

1. the ``device`` argument, else the ``XRAYRASTER_CL_DEVICE`` environment variable: either
   ``"P:D"`` (platform and device indices as :func:`list_devices` prints them) or a
   case-insensitive piece of ``"<platform name> <device name>"`` (e.g. ``"nvidia"``, ``"pocl"``);
2. otherwise the fastest device that compiles a kernel: GPUs before accelerators before CPUs,
   then the most compute units × clock. A device whose compiler fails is passed over: PyPI's PoCL
   (LLVM 14) cannot compile for a CPU its LLVM does not know (AMD Zen 5 is "unknown target CPU
   'generic'"), where a distribution's newer PoCL beside it can.

Without an OpenCL driver, or with none that compiles, the error says how to get one.
"""

from __future__ import annotations

import logging
import os
import re
import signal
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..core.errors import OpenCLError
from ..core.shader_files import read_shader

log = logging.getLogger(__name__)

INSTALL_HINT = (
    "xrayraster reconstructs with OpenCL. Install a driver: 'pip install pocl-binary-distribution' "
    "(PoCL, runs on any CPU) or the GPU vendor's OpenCL driver (an ICD, e.g. NVIDIA's driver or ROCm)."
)
COMPILER_HINT = (
    "A CPU newer than the LLVM of PyPI's PoCL ('unknown target CPU') needs a newer PoCL: on Debian or Ubuntu, "
    "'apt-get install pocl-opencl-icd'; or a GPU vendor's OpenCL driver."
)
# The smallest kernel that exercises the device's compiler and its built-in library (sqrt).
_PROBE_SOURCE = "__kernel void probe(__global float *x) { x[get_global_id(0)] = sqrt(2.0f); }"
_probe_failures: dict[str, str | None] = {}  # device index -> why it cannot compile (None: it can)


@dataclass(frozen=True)
class DeviceInfo:
    index: str  # "P:D"
    platform: str
    name: str
    kind: str  # "GPU", "CPU", "ACCELERATOR", ...
    compute_units: int
    clock_mhz: int
    global_mem: int  # bytes
    max_alloc: int  # bytes
    local_mem: int  # bytes
    max_work_group: int

    def __str__(self) -> str:
        return (f"{self.index} {self.platform} / {self.name} ({self.kind}, {self.compute_units} compute units, "
                f"{self.global_mem / 2**30:.1f} GiB)")


def _cl():
    try:
        import pyopencl
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise OpenCLError(f"pyopencl cannot be imported ({exc}): 'pip install pyopencl'. {INSTALL_HINT}") from None
    return pyopencl


def _devices():
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:
        raise OpenCLError(f"no OpenCL platform found ({exc}). {INSTALL_HINT}") from None
    found = []
    for p, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue  # a platform without devices (e.g. an ICD whose hardware is absent)
        for d, device in enumerate(devices):
            info = DeviceInfo(
                f"{p}:{d}", platform.name.strip(), device.name.strip(), cl.device_type.to_string(device.type),
                int(device.max_compute_units), int(device.max_clock_frequency), int(device.global_mem_size),
                int(device.max_mem_alloc_size), int(device.local_mem_size), int(device.max_work_group_size))
            found.append((info, device))
    if not found:
        raise OpenCLError(f"OpenCL platforms exist but none has a device. {INSTALL_HINT}")
    return found


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device on this machine."""
    return [info for info, _ in _devices()]


def _rank(info: DeviceInfo) -> tuple:
    kind = 2 if "GPU" in info.kind else 1 if "ACCELERATOR" in info.kind else 0
    return kind, info.compute_units * max(info.clock_mhz, 1)


def choose_device(request: str | None = None):
    """(DeviceInfo, pyopencl.Device) for ``request`` (see the module docstring)."""
    request = request or os.environ.get("XRAYRASTER_CL_DEVICE") or None
    found = _devices()
    if request is None:
        return _first_that_compiles(sorted(found, key=lambda item: _rank(item[0]), reverse=True))
    request = request.strip()
    if re.fullmatch(r"\d+:\d+", request):
        match = [item for item in found if item[0].index == request]
    else:
        match = [item for item in found if request.lower() in f"{item[0].platform} {item[0].name}".lower()]
    if not match:
        listing = "; ".join(str(info) for info, _ in found)
        raise OpenCLError(f"OpenCL device {request!r} (device option or XRAYRASTER_CL_DEVICE) matches none of: {listing}")
    return max(match, key=lambda item: _rank(item[0]))


def _first_that_compiles(ranked):
    """The first of ``ranked`` (DeviceInfo, device) pairs whose compiler builds a probe kernel."""
    failures = []
    for info, device in ranked:
        why = _probe_failure(info, device)
        if why is None:
            return info, device
        log.info("OpenCL device %s passed over: %s", info, why)
        failures.append(f"{info}: {why}")
    raise OpenCLError(f"no OpenCL device compiles a kernel ({'; '.join(failures)}). {COMPILER_HINT}")


def _probe_failure(info: DeviceInfo, device) -> str | None:
    """Why ``device`` cannot build a kernel (its compiler's first complaint), or None; once a process."""
    if info.index not in _probe_failures:
        cl = _cl()
        try:
            with signals_held():
                cl.Program(cl.Context([device]), _PROBE_SOURCE).build()
            _probe_failures[info.index] = None
        except cl.Error as exc:
            log_lines = [line.strip() for line in str(exc).splitlines() if "error" in line.lower()]
            _probe_failures[info.index] = (log_lines[-1] if log_lines else str(exc).splitlines()[0])[:200]
    return _probe_failures[info.index]


@contextmanager
def signals_held():
    """SIGINT and SIGTERM kept from this thread while an OpenCL compiler runs in it. PoCL compiles
    in-process, and a signal that cuts into its compiler's system calls makes the compiler print its
    own error to stderr (CI saw "1 error generated." before xrayraster's one line on a SIGTERM).
    Held, the signal goes to another thread or waits for the block's end; either way Python runs its
    handler once the compile has returned, as it would have."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class CLContext:
    """An OpenCL context and queue on one device, plus its compiled kernels (built once each).

    Use as a context manager or call :meth:`release`.
    """

    def __init__(self, device: str | None = None):
        cl = _cl()
        self.info, self.device = choose_device(device)
        self.ctx = cl.Context([self.device])
        self.queue = cl.CommandQueue(self.ctx)
        self._programs = {}
        self._kernels = {}
        log.info("OpenCL device %s", self.info)

    def kernel(self, source: str, name: str, defines: dict | None = None, optional: bool = False):
        """Kernel ``name`` of ``shaders/<source>`` built with ``-D`` ``defines`` (built once, then
        reused). ``optional``: None when the source leaves the kernel out on this device."""
        cl = _cl()
        options = tuple(f"-D{k}={v}" for k, v in sorted((defines or {}).items()))
        if (source, options) not in self._programs:
            try:
                with signals_held():
                    self._programs[source, options] = cl.Program(self.ctx, read_shader(source)).build(
                        options=list(options))
            except cl.RuntimeError as exc:
                raise OpenCLError(f"OpenCL kernel {source} failed to build on {self.info}: {exc}"
                                  + (f". {COMPILER_HINT}" if "unknown target CPU" in str(exc) else "")) from None
        program = self._programs[source, options]
        if (source, options, name) not in self._kernels:
            if name not in program.kernel_names.split(";"):
                if optional:
                    return None
                raise OpenCLError(f"OpenCL program {source} has no kernel {name!r} on {self.info}")
            self._kernels[source, options, name] = cl.Kernel(program, name)
        return self._kernels[source, options, name]

    def buffer(self, size_or_array, flags: str = "rw"):
        """A device buffer: of ``size`` bytes, or holding a copy of a NumPy array."""
        cl = _cl()
        mode = {"r": cl.mem_flags.READ_ONLY, "w": cl.mem_flags.WRITE_ONLY, "rw": cl.mem_flags.READ_WRITE}[flags]
        if isinstance(size_or_array, np.ndarray):
            return cl.Buffer(self.ctx, mode | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(size_or_array))
        return cl.Buffer(self.ctx, mode, int(size_or_array))

    def release(self) -> None:
        self._programs = {}
        self._kernels = {}
        self.queue = None
        self.ctx = None

    close = release

    def __enter__(self) -> "CLContext":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

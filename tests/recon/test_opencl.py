"""OpenCL device choice: the fastest by default, by index or name on request (argument or
XRAYRASTER_CL_DEVICE), and errors that say how to get a driver."""

from __future__ import annotations

from pathlib import Path

import pytest

from xrayraster.recon import opencl
from xrayraster.recon.opencl import CLContext, DeviceInfo, OpenCLError

ROOT = Path(__file__).resolve().parents[2]


def _info(index, kind, units, clock=1000, platform="P", name="D"):
    return DeviceInfo(index, platform, name, kind, units, clock, 2**30, 2**28, 2**15, 256)


def test_fastest_prefers_gpus_then_compute(monkeypatch):
    found = [(_info("0:0", "CPU", 64, name="big cpu"), "cpu"), (_info("1:0", "GPU", 20, name="small gpu"), "gpu"),
             (_info("1:1", "GPU", 80, name="big gpu"), "gpu2")]
    monkeypatch.setattr(opencl, "_devices", lambda: found)
    monkeypatch.setattr(opencl, "_probe_failure", lambda info, device: None)
    monkeypatch.delenv("XRAYRASTER_CL_DEVICE", raising=False)
    assert opencl.choose_device()[0].name == "big gpu"
    assert opencl.choose_device("0:0")[0].name == "big cpu"
    assert opencl.choose_device("SMALL")[0].name == "small gpu"
    monkeypatch.setenv("XRAYRASTER_CL_DEVICE", "cpu")
    assert opencl.choose_device()[0].name == "big cpu"
    with pytest.raises(OpenCLError, match=r"'tpu' .* matches none of: 0:0 P / big cpu"):
        opencl.choose_device("tpu")


def test_a_device_whose_compiler_fails_is_passed_over(monkeypatch):
    """PyPI's PoCL (LLVM 14) on a CPU its LLVM does not know fails every build: the next device is
    chosen, and with none left the error says how to get a compiler that knows the CPU."""
    found = [(_info("0:0", "CPU", 2, name="new pocl"), "new"), (_info("1:0", "CPU", 4, name="old pocl"), "old")]
    monkeypatch.setattr(opencl, "_devices", lambda: found)
    monkeypatch.delenv("XRAYRASTER_CL_DEVICE", raising=False)
    failing = {"old": "error: unknown target CPU 'generic'"}
    monkeypatch.setattr(opencl, "_probe_failure", lambda info, device: failing.get(device))
    assert opencl.choose_device()[0].name == "new pocl"  # the faster "old pocl" cannot compile
    failing["new"] = "error: something else"
    with pytest.raises(OpenCLError, match=r"no OpenCL device compiles a kernel \(1:0 P / old pocl .*unknown target "
                                          r"CPU 'generic'; 0:0 P / new pocl .*apt-get install pocl-opencl-icd"):
        opencl.choose_device()


def test_the_chosen_device_compiles_a_kernel(cl):
    """Whatever this machine has (PyPI's PoCL, a distribution's, a GPU), the default device builds and runs."""
    info, device = opencl.choose_device()
    assert opencl._probe_failure(info, device) is None


def test_no_platform_says_how_to_install_pocl(monkeypatch):
    import pyopencl as cl

    def none():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", none)
    with pytest.raises(OpenCLError, match="no OpenCL platform found.*pip install pocl-binary-distribution"):
        CLContext()


def test_the_real_devices_are_listed_and_usable(cl):
    devices = opencl.list_devices()
    assert devices and all(d.global_mem > 0 and d.compute_units > 0 for d in devices)
    again = CLContext(cl.info.index)  # by index, as list_devices prints it
    assert again.info == cl.info
    assert again.kernel("fdk_filter.cl", "filter_rows") is again.kernel("fdk_filter.cl", "filter_rows")  # built once
    assert again.kernel("fdk_filter.cl", "no_such_kernel", optional=True) is None
    with pytest.raises(OpenCLError, match="has no kernel 'no_such_kernel'"):
        again.kernel("fdk_filter.cl", "no_such_kernel")
    again.release()


def test_a_signal_during_a_kernel_build_waits_for_the_compiler(cl, monkeypatch):
    """PoCL compiles in-process; a SIGINT or SIGTERM cutting into its compiler's system calls had it
    print its own error before the command's one line (CI, once in 23 runs). Kernels are built with
    both held in the building thread (another thread takes the signal, or it waits), and a signal
    held is delivered when the block ends."""
    import os
    import signal
    import subprocess
    import sys
    import threading

    pyopencl = opencl._cl()
    build, masks = pyopencl.Program.build, []

    def recording(self, *args, **kwargs):
        masks.append(signal.pthread_sigmask(signal.SIG_BLOCK, set()))
        return build(self, *args, **kwargs)

    monkeypatch.setattr(pyopencl.Program, "build", recording)
    cl.kernel("fdk_filter.cl", "filter_rows", {"HELD_SIGNALS_TEST": 1})  # a define of its own: a fresh build
    assert masks and {signal.SIGINT, signal.SIGTERM} <= masks[-1]
    assert not {signal.SIGINT, signal.SIGTERM} & signal.pthread_sigmask(signal.SIG_BLOCK, set())
    assert threading.current_thread() is threading.main_thread()

    # A thread of its own, the child's only one (no BLAS threads): SIGTERM stays pending until the
    # block ends, then does what it does by default.
    code = ("import os, signal\nfrom xrayraster.recon.opencl import signals_held\n"
            "with signals_held():\n    os.kill(os.getpid(), signal.SIGTERM)\n"
            "    print('held' if signal.SIGTERM in signal.sigpending() else 'not held', flush=True)\n"
            "print('after the block', flush=True)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert run.stdout == "held\n" and run.returncode == -signal.SIGTERM, (run.stdout, run.stderr)

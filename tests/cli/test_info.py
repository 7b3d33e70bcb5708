"""``xrayraster info``: its facts agree with what GL, OpenCL and a stopwatch say independently; a
missing driver is a line, not a crash (exit 0); ``--no-bench`` is quick; bad arguments exit 2."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import time

import numpy as np
import pytest

import xrayraster as xr
from xrayraster import cli
from xrayraster.cli import info
from xrayraster.core.errors import GLContextError, OpenCLError
from xrayraster.gl import context
from xrayraster.recon import opencl

KEYS = {
    "gl": {"backend", "renderer", "vendor", "version", "version_code", "free_video_memory_bytes", "error", "env"},
    "opencl": {"devices", "picked", "error", "env"},
    "memory": {"available_bytes", "total_bytes"},
    "host": {"system", "machine", "cpu", "cores", "cores_usable"},
    "python": {"python", "xrayraster", *info.DISTRIBUTIONS},
    "bench": {"detector_pixels", "views", "voxels", "triangles", "render_method", "views_per_s",
              "fdk_voxel_updates_per_s", "fdk_first_call_s", "view_passes", "fdk_calls", "seconds"},
}
GL_MAX_TEXTURE_SIZE = 0x0D33


def run_info(*args: str) -> tuple[int, str]:
    """``xrayraster info ARGS`` in this process: (exit status, stdout)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = cli.main(["info", *args])
    return status, out.getvalue()


@pytest.fixture(scope="module")
def facts(gl, cl):
    """``xrayraster info --json``, bench included, run once (about 3 s on 2 CPU cores)."""
    status, out = run_info("--json")
    assert status == 0
    return json.loads(out)


def missing_opencl():
    raise OpenCLError(f"no OpenCL platform found (clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR). "
                      f"{opencl.INSTALL_HINT}")


def missing_gl():
    raise GLContextError(f"no OpenGL context could be created (egl: no display; osmesa: libOSMesa not found). "
                         f"{context.INSTALL_HINT}")


@pytest.mark.slow
def test_the_json_has_every_fact_with_numbers_as_numbers(facts):
    assert set(facts) == set(KEYS)
    for key, fields in KEYS.items():
        assert set(facts[key]) == fields, key
    assert facts["gl"]["error"] is None and facts["opencl"]["error"] is None
    assert isinstance(facts["gl"]["version_code"], int) and facts["gl"]["version_code"] >= 430
    assert facts["memory"]["total_bytes"] >= facts["memory"]["available_bytes"] > 0
    assert facts["host"]["cores"] >= facts["host"]["cores_usable"] >= 1
    assert facts["python"]["xrayraster"] == xr.__version__
    bench = facts["bench"]
    for key in ("views_per_s", "fdk_voxel_updates_per_s", "fdk_first_call_s", "seconds"):
        assert isinstance(bench[key], float) and math.isfinite(bench[key]) and bench[key] > 0, key
    assert (bench["detector_pixels"], bench["views"], bench["voxels"]) == (256, 64, 128)
    assert isinstance(bench["triangles"], int) and bench["triangles"] > 1000
    assert bench["seconds"] < 30  # about 3 s here; the README says so


@pytest.mark.slow
def test_the_gl_facts_are_what_moderngl_reports(facts, gl):
    assert facts["gl"]["backend"] == gl.backend
    assert facts["gl"]["renderer"] == gl.ctx.info["GL_RENDERER"]
    assert facts["gl"]["vendor"] == gl.ctx.info["GL_VENDOR"]
    assert facts["gl"]["version"] == gl.ctx.info["GL_VERSION"]
    assert facts["gl"]["env"]["XRAYRASTER_GL"] == os.environ.get("XRAYRASTER_GL")


@pytest.mark.slow
def test_the_opencl_device_picked_is_the_one_pyopencl_lists_there(facts, cl):
    import pyopencl

    platforms = pyopencl.get_platforms()
    picked = facts["opencl"]["picked"]
    p, d = map(int, picked["index"].split(":"))
    device = platforms[p].get_devices()[d]
    assert picked["name"] == device.name.strip() and picked["platform"] == platforms[p].name.strip()
    assert picked["global_mem"] == device.global_mem_size
    assert picked["index"] == cl.info.index  # the device a reconstruction gets by default
    listed = []
    for platform in platforms:
        with contextlib.suppress(pyopencl.Error):  # a platform without devices, as recon/opencl.py skips it
            listed += [device.name.strip() for device in platform.get_devices()]
    assert [device["name"] for device in facts["opencl"]["devices"]] == listed


@pytest.mark.slow
def test_views_a_second_agree_with_a_stopwatch_within_3x(facts, gl):
    """The bench's figure against rendering its sample's first views here, timed apart."""
    sample, centre = info.bench_sample()
    geometry, _ = info.bench_geometry(sample.box)
    scene = sample.scene(transform=centre)
    with xr.Renderer(geometry, context=gl) as renderer:
        renderer.path_lengths(scene, 0)
        passes = []
        for _ in range(2):
            start = time.perf_counter()
            for view in range(16):
                renderer.path_lengths(scene, view)
            passes.append(16 / (time.perf_counter() - start))
    assert 1 / 3 < facts["bench"]["views_per_s"] / max(passes) < 3, (facts["bench"]["views_per_s"], passes)
    assert facts["bench"]["triangles"] == scene.num_triangles


@pytest.mark.slow
def test_fdk_voxel_updates_agree_with_a_stopwatch_within_3x(facts, cl):
    geometry, volume = info.bench_geometry(info.bench_sample()[0].box)
    lines = np.zeros((64, 256, 256), np.float32)
    times = []
    for _ in range(3):
        start = time.perf_counter()
        xr.fdk(lines, geometry, volume, context=cl)
        times.append(time.perf_counter() - start)
    measured = 128**3 * 64 / min(times[1:])
    assert 1 / 3 < facts["bench"]["fdk_voxel_updates_per_s"] / measured < 3, (facts["bench"], times)


def test_no_bench_is_quick_and_one_line_a_fact():
    run_info("--no-bench")  # the first run in a process builds OpenCL's probe kernel
    start = time.perf_counter()
    status, out = run_info("--no-bench")
    assert time.perf_counter() - start < 3
    assert status == 0
    assert [line.split(":")[0] for line in out.splitlines()] == ["gl", "opencl", "memory", "host", "python"]
    assert "XRAYRASTER_GL unset" in out.splitlines()[0] or "XRAYRASTER_GL=" in out.splitlines()[0]
    assert "XRAYRASTER_CL_DEVICE" in out.splitlines()[1]
    status, out = run_info("--no-bench", "--json")
    assert status == 0 and json.loads(out)["bench"] is None


def test_a_missing_opencl_driver_is_a_line_and_exit_0(monkeypatch):
    monkeypatch.setattr(opencl, "list_devices", missing_opencl)
    status, out = run_info("--no-bench")
    assert status == 0
    line = out.splitlines()[1]
    assert line.startswith("opencl: none: no OpenCL platform found") and "pip install pocl-binary-distribution" in line
    status, out = run_info("--no-bench", "--json")
    assert status == 0
    facts = json.loads(out)["opencl"]
    assert facts["picked"] is None and facts["devices"] == [] and "pocl-binary-distribution" in facts["error"]


def test_without_gl_and_opencl_the_bench_says_what_it_skipped(monkeypatch):
    monkeypatch.setattr(opencl, "list_devices", missing_opencl)
    monkeypatch.setattr(info, "GLContext", missing_gl)
    status, out = run_info()
    assert status == 0
    gl_line, *_, bench_line = out.splitlines()
    assert gl_line.startswith("gl: none: no OpenGL context could be created") and "apt-get install libegl1" in gl_line
    assert bench_line.startswith("bench: views: no GL, FDK: no OpenCL device")


def test_the_environment_variables_change_the_choice_and_are_shown(monkeypatch, cl):
    devices = opencl.list_devices()
    monkeypatch.setenv("XRAYRASTER_CL_DEVICE", devices[-1].index)
    monkeypatch.setenv("POCL_DEVICES", "pthread")  # a loader's variable: shown when set
    facts = info.opencl_facts()
    assert facts["picked"]["index"] == devices[-1].index
    assert f"(XRAYRASTER_CL_DEVICE={devices[-1].index}; POCL_DEVICES=pthread)" in info.opencl_line(facts)
    monkeypatch.setenv("XRAYRASTER_GL", "vulkan")
    gl, error = info.open_gl()
    line = info.gl_line(info.gl_facts(gl, error))
    assert gl is None and line == "gl: none: unknown GL backend 'vulkan': use 'egl' or 'osmesa' (XRAYRASTER_GL) " \
                                   "(XRAYRASTER_GL=vulkan: forced)"


def test_gl_integers_read_what_moderngl_reads(gl):
    """The query behind the GPU's free memory (NVIDIA's and AMD's extensions, absent from llvmpipe)."""
    assert info.gl_integers(gl, GL_MAX_TEXTURE_SIZE) == [gl.ctx.info["GL_MAX_TEXTURE_SIZE"]]
    assert info.gl_integers(gl, 0xFFFF) is None  # a name the driver does not know, its error cleared
    assert gl.ctx.error == "GL_NO_ERROR"
    free = info.gl_free_video_memory_bytes(gl)
    assert free is None or free > 0


def test_bad_arguments_exit_2():
    with pytest.raises(SystemExit) as exc:
        cli.main(["info", "--bench"])
    assert exc.value.code == 2

"""Peak memory of a streamed reconstruction: views made batch by batch go into xr.FDKStream.

    python -m scripts.fdk_stream_memory                      # 801 views of 1024², a 512³ volume
    python -m scripts.fdk_stream_memory --views 90 --pixels 256 --voxels 128

The views are random line integrals drawn one batch at a time (the reconstruction's cost does not
depend on their values), as `xrayraster scan` renders them, so the whole stack (801 × 1024² float32:
3.4 GB) never exists. Prints the time, the peak resident memory of the process and the volume's
size, whose small multiple the peak should be.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

import xrayraster as xr

from .common import machine_info


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=801)
    parser.add_argument("--pixels", type=int, default=1024, help="detector rows and columns")
    parser.add_argument("--voxels", type=int, default=512, help="volume side")
    parser.add_argument("--batch", type=int, default=32, help="views per batch (xrayraster scan: 32)")
    args = parser.parse_args(argv)
    # The twin's distances; pixels sized so the field of view spans the volume at the axis.
    voxel_mm = 29.6 / args.voxels
    geometry = xr.ConeBeamGeometry(60.0, 140.0, (args.pixels,) * 2, voxel_mm * args.voxels / args.pixels * 140 / 60,
                                   xr.full_circle(args.views))
    volume = xr.VolumeGeometry((args.voxels,) * 3, voxel_mm)
    rng = np.random.default_rng(0)
    print("machine:", machine_info())
    start = time.perf_counter()
    with xr.FDKStream(geometry, volume, batch_views=args.batch) as stream:
        for first in range(0, args.views, stream.batch_views):
            count = min(stream.batch_views, args.views - first)
            stream.add(first, rng.random((count, args.pixels, args.pixels), dtype=np.float32))
        result = stream.result()
    seconds = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    volume_mib = result.data.nbytes / 2**20
    stack_mib = args.views * args.pixels**2 * 4 / 2**20
    print(f"{args.views} views of {args.pixels}² into {args.voxels}³ in {seconds:.1f} s (batches of {stream.batch_views});"
          f" peak memory {peak_mib:.0f} MiB = {peak_mib / volume_mib:.2f} × the volume ({volume_mib:.0f} MiB); "
          f"the whole stack would be {stack_mib:.0f} MiB")


if __name__ == "__main__":
    main()

"""Peer codes the benchmarks compare with (gVirtualXRay, RTK, VTK): each module loads its library on first use."""

"""Reconstruction in OpenCL: device context, FDK weights, ramp filter, backprojection."""

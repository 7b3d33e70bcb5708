"""The names a dataset build writes and its readers look for, written once: the build (``build``),
its layouts (``layouts``) and ``xr.ml`` (which must not load the build to read one) import them here."""

GENERATOR = "xrayraster build"  # the "generator" of every record a build writes, and of its NIfTI headers
RECORD_NAME = "build.json"  # the build directory's record, written first: the layout and the dataset's name
FAILED_NAME = "failed.csv"  # the samples that failed, with their drawn values and errors
GALLERY_NAME = "gallery.png"  # the first finished samples, side by side

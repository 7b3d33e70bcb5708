"""Independent references that tests and benchmarks compare xrayraster with: analytic chord
lengths and rays from the documented conventions, analytic phantoms and their exact projections,
FDK in float64 NumPy, float64 path lengths through meshes, classical segmentation baselines and
Dice scores, TexGen as a weave peer; and the headless browser the preview's page tests drive.
Not shipped, and never imported by the package (import-linter)."""

"""Independent references that tests and benchmarks compare xrayraster with: analytic chord
lengths and rays from the documented conventions, analytic phantoms and their exact projections,
and FDK in float64 NumPy. Not shipped, and never imported by the package (import-linter)."""

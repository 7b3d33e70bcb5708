"""Values every stage shares: scan and volume geometry, transforms, errors, choices; NumPy only."""

"""What is scanned: closed meshes, scenes of objects with priorities and labels, materials."""

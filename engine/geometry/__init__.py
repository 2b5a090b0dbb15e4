"""Surfaces and their geometry: parametric and read roofs, projection onto them, nearest points,
symmetry planes, the fine mesh a shell is analysed on, and form finding."""

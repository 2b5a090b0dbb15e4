"""From the stress field to the grid: the guiding metric, the statics-aware Voronoi remesh (the
clustering, the cell extraction, the clean-up), the optimiser of regular cells and planar panels,
the grid's quality figures and the reference quad and triangle grids."""

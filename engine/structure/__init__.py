"""Structural analysis: the shell, the beam grid as a frame (elements, the condensed factor, linear,
buckling and the co-rotational path), the factorisations, loads, supports and the imperfection
protocol."""

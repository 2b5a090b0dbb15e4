"""gridshell fabrication: joints, beams, panels, nesting, assembly and drawings from a checked grid-shell.

May import ``engine`` types; never ``workflow``. CAD and DXF libraries are imported lazily.
"""

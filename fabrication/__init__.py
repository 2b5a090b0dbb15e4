"""gridshell fabrication: joints, beams, panels, nesting, assembly and drawings from a checked grid-shell.

May import ``engine`` types; never ``workflow``. CAD and DXF libraries are imported lazily.
"""

import logging

# the library logs to its module loggers; an application (the CLI: --verbose) adds handlers
logging.getLogger(__name__).addHandler(logging.NullHandler())

